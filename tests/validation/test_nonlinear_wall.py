"""The temperature-dependent wall of the known-truth experiments against its references.

``helpers/nonlinear_wall.py`` makes the measurements of the ``conductivity`` experiment
(``test_coverage.py``); these checks keep it honest: with no temperature dependence it is
the calibrated wall (its exact time scheme, same mesh), its steady state is the closed
form of a conductivity linear in temperature (Kirchhoff transform), and the transient
settles on it.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.simulators.base import Forcing
from bayescal.simulators.wall import MultilayerWall
from nonlinear_wall import REALISTIC, REFERENCE, ConductivityWall
from virtual_wall import PAPER_TRUTH, PER_DAY, STEP, paper_wall, surface_temperatures


@pytest.fixture(scope="module")
def weather() -> Forcing:
    return Forcing(STEP, surface_temperatures(np.random.default_rng(3), 3 * PER_DAY))


def test_without_temperature_dependence_it_is_the_calibrated_wall(weather: Forcing) -> None:
    base = paper_wall()
    exact = MultilayerWall(
        base.layers,
        parameters={
            "k_cb": ["concrete.conductivity"],
            "cp_cb": ["concrete.specific_heat"],
            "cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"],
        },
        boundary="surface",
        scheme="exact",
    )
    want = exact.simulate(PAPER_TRUTH, weather)["heat_flux_in"]
    got = ConductivityWall({}, wall=exact).simulate(PAPER_TRUTH, weather)["heat_flux_in"]
    # the same mesh and exact time integration: only the ODE solver's tolerance is left
    assert np.max(np.abs(got - want)) < 1e-5 * np.max(np.abs(want))


def test_its_steady_state_is_the_kirchhoff_closed_form() -> None:
    wall = ConductivityWall(REALISTIC)
    t_out, t_in = -5.0, 22.0
    temps = wall.steady(PAPER_TRUTH, t_out, t_in)
    nodes = wall.wall.propagator(PAPER_TRUTH, STEP).mesh.interface_nodes
    layers = wall.wall.wall_state(PAPER_TRUTH).layers
    # q = k_10 / L [dT + beta/2 ((T1 - Tr)^2 - (T2 - Tr)^2)] through every layer
    fluxes = []
    for layer, i, j in zip(layers, nodes[:-1], nodes[1:], strict=True):
        a, b, beta = temps[i], temps[j], REALISTIC[layer.name]
        kirchhoff = (a - b) + 0.5 * beta * ((a - REFERENCE) ** 2 - (b - REFERENCE) ** 2)
        fluxes.append(layer.conductivity / layer.thickness * kirchhoff)
    assert np.ptp(fluxes) < 1e-10 * abs(fluxes[0])
    derived = wall.derived_at(PAPER_TRUTH, t_out, t_in)
    assert derived["R_wall"] == pytest.approx((t_out - t_in) / fluxes[0], rel=1e-10)
    # the warm inner board conducts better, the cold outer one worse: not the 10 °C sum
    r10 = paper_wall().derived(PAPER_TRUTH)["R_wall"]
    assert abs(derived["R_wall"] / r10 - 1.0) > 1e-3


def test_it_settles_on_its_steady_state_and_differs_from_the_constant_wall(
    weather: Forcing,
) -> None:
    wall = ConductivityWall(REALISTIC)
    constant = paper_wall().simulate(PAPER_TRUTH, weather)["heat_flux_in"]
    flux = wall.simulate(PAPER_TRUTH, weather)["heat_flux_in"]
    # held at the first day's end temperatures for five days, the flux settles on the
    # steady one of the nonlinear wall
    bc = {k: np.concatenate([v[: PER_DAY + 1], np.full(5 * PER_DAY, v[PER_DAY])])
          for k, v in weather.series.items()}  # fmt: skip
    settled = wall.simulate(PAPER_TRUTH, Forcing(STEP, bc))["heat_flux_in"][-1]
    r = wall.derived_at(PAPER_TRUTH, bc["temp_surf_out"][-1], bc["temp_surf_in"][-1])["R_wall"]
    steady = (bc["temp_surf_out"][-1] - bc["temp_surf_in"][-1]) / r
    assert settled == pytest.approx(steady, rel=1e-3)
    # the model error is of the size the experiment is meant to test: a few hundredths
    # of a W/m², comparable to the noise SD (0.084 W/m²)
    diff = flux - constant
    assert 0.01 < np.sqrt(np.mean(diff[PER_DAY:] ** 2)) < 0.2
