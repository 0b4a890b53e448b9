"""A virtual wall whose resistance split needs a second sensor (issue 15, several sensors).

The paper's wall (glass-fibre board | aerated concrete | glass-fibre board)
with two unknowns: the boards' conductivity ``k_fb`` and the concrete's
``k_cb``. The inside heat flux fixes the wall's total resistance well and its
split between boards and concrete only through the dynamics; the temperature
at the concrete / inside-board interface (``temp_interface_2``) fixes the
split. "Measurements": the truth plus white noise (flux SD 0.0837 W/m², the
paper's; interface temperature SD 0.05 K, a calibrated thermocouple).
"""

from __future__ import annotations

import numpy as np

from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.design import UniformPrior, latin_hypercube
from bayescal.emulator.assemble import Assembled, NoiseSpec, assemble
from bayescal.emulator.training import train
from bayescal.periods import layout_periods
from bayescal.simulators.base import Forcing
from bayescal.simulators.fvm import Layer
from bayescal.simulators.wall import MultilayerWall
from coverage import band_coverage, draw_picks
from virtual_wall import PER_DAY, STEP, surface_temperatures

OUTPUTS = ("heat_flux_in", "temp_interface_2")
NOISE_SD = {"heat_flux_in": float(np.sqrt(0.007)), "temp_interface_2": 0.05}
PRIORS = {"k_fb": UniformPrior(0.025, 0.04), "k_cb": UniformPrior(0.08, 0.16)}
TRUTH = {"k_fb": 0.0316, "k_cb": 0.124}
BOARD, CONCRETE = 0.027, 0.150  # thicknesses [m]


def split_wall() -> MultilayerWall:
    """The wall with ``k_fb`` (both boards) and ``k_cb`` as parameters, both outputs."""
    layers = [
        Layer("fb_out", BOARD, 0.0316, 116.6, 840.0),
        Layer("concrete", CONCRETE, 0.12, 552.0, 800.0),
        Layer("fb_in", BOARD, 0.0316, 116.6, 840.0),
    ]
    targets = {
        "k_fb": ["fb_out.conductivity", "fb_in.conductivity"],
        "k_cb": ["concrete.conductivity"],
    }
    return MultilayerWall(layers, parameters=targets, boundary="surface", outputs=OUTPUTS)


def board_share(k_fb: np.ndarray, k_cb: np.ndarray) -> np.ndarray:
    """The boards' share of the wall's resistance. [-]"""
    r_fb = 2.0 * BOARD / k_fb
    return r_fb / (r_fb + CONCRETE / k_cb)


def calibrate_split(
    seed: int, outputs: tuple[str, ...], train_days: int = 14, test_days: int = 3
) -> tuple[Posterior, dict[str, dict[str, tuple[float, float]]]]:
    """Calibrate on ``outputs``; the posterior and its band coverage per output.

    The bands are those of every output (measured or not by the calibration),
    from the wall re-run at 40 posterior draws.
    """
    rng = np.random.default_rng([seed, 151])
    warm = 4
    n = PER_DAY * (warm + train_days + test_days)
    bc = surface_temperatures(rng, n)
    forcing = Forcing(STEP, bc)
    wall = split_wall()
    design = latin_hypercube(PRIORS, 30, seed=seed)
    sims = [wall.simulate(design.row(k), forcing) for k in range(30)]
    clean = wall.simulate(TRUTH, forcing)
    measured = {o: clean[o] + rng.normal(0.0, NOISE_SD[o], n) for o in OUTPUTS}
    layout = layout_periods(n, PER_DAY, PER_DAY * warm, PER_DAY * test_days)
    a: Assembled = assemble(
        design,
        {o: np.array([s[o] for s in sims]) for o in outputs},
        {o: measured[o] for o in outputs},
        bc,
        layout,
        variance=0.999,
        history=1,
        scale="output",
        noise={o: NoiseSpec("white") for o in outputs},
    )
    em = train(a, n_burn=300, n_draws=100, n_chains=1, seed=seed)
    post = calibrate(
        em, a, n_chains=4, n_burn=2000, n_draws=1500, seed=seed, backend="processes",
        observations=a.observations,
    )  # fmt: skip
    pick = draw_picks(post)
    theta = post.draws.reshape(-1, len(post.names))[pick]
    reruns = [
        wall.simulate(dict(zip(post.names, map(float, row), strict=True)), forcing) for row in theta
    ]
    runs = {o: np.array([r[o] for r in reruns]) for o in outputs}
    cover = band_coverage(a, post, {o: measured[o] for o in outputs}, runs, pick)
    return post, cover
