"""Fixtures shared by several rooms' tests (built once per test session).

The emulators below are trained the same way in the emulator, calibration,
NUTS and discrepancy tests; building them once saves minutes of ``make test``.
They are frozen objects: a test cannot change what another sees.
"""

from __future__ import annotations

import pytest

from bayescal.emulator.assemble import Assembled, assemble
from bayescal.emulator.gp import Emulator
from bayescal.emulator.training import train
from virtual_wall import VirtualExperiment, virtual_experiment


@pytest.fixture(scope="session")
def paper_wall() -> tuple[VirtualExperiment, Assembled, Emulator]:
    """The paper-size virtual wall (R = 30 runs x m* = 25 days, basis at 99 %) and its emulator."""
    ve = virtual_experiment(seed=0)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, variance=0.99)
    return ve, a, train(a, n_burn=400, n_draws=100, n_chains=1, seed=1)


@pytest.fixture(scope="session")
def small_wall() -> tuple[VirtualExperiment, Assembled, Emulator]:
    """A small virtual wall (8 runs x 6 days, 2 basis vectors) and its emulator."""
    ve = virtual_experiment(seed=4, runs=8, periods=6, warmup_days=2, test_days=0)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2)
    return ve, a, train(a, n_burn=100, n_draws=20, n_chains=1, seed=0)
