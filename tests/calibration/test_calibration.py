"""Calibration of theta* (eq. 16) on the virtual wall with known truth (paper's Table 3)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from bayescal.calibration.kron import make_algebra
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.calibration.target import CalibrationPosterior
from bayescal.design import BetaPrior, UniformPrior
from bayescal.emulator.assemble import Assembled, assemble
from bayescal.emulator.gp import Emulator
from bayescal.emulator.training import train
from bayescal.errors import ConfigError
from virtual_wall import PRIORS, VirtualExperiment, random_truth, virtual_experiment

NAMES = ("k_cb", "cp_cb", "cp_fb")
VARIANCE = 0.99  # basis variance fraction; see test_default_basis_* for 0.90


def _prior_sd(name: str) -> float:
    return PRIORS[name].width / np.sqrt(12.0)  # SD of the uniform prior


def _fit(seed: int, truth: dict[str, float] | None = None) -> tuple[VirtualExperiment, Assembled]:
    ve = virtual_experiment(seed=seed, truth=truth)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, variance=VARIANCE)
    return ve, a


@pytest.fixture(scope="module")
def small(small_wall: tuple[VirtualExperiment, Assembled, Emulator]) -> tuple[Assembled, Emulator]:
    _, a, em = small_wall
    return a, em


def test_kronecker_and_dense_log_posteriors_agree(small: tuple[Assembled, Emulator]) -> None:
    a, em = small
    priors = list(a.priors.values())
    targets = [
        CalibrationPosterior(
            make_algebra(kind, em.theta, em.x, em.kernels, em.basis.ktk, em.w, a.w_star),
            priors,
            em.lam_prior,
            a.lam_star_prior,
        )
        for kind in ("kronecker", "dense")
    ]
    rng = np.random.default_rng(0)
    for _ in range(5):
        v = np.concatenate([rng.random(3), [em.lam, rng.uniform(5.0, 50.0)]])
        fast, ref = (t(v) for t in targets)
        # Schur/eigen path vs dense Cholesky of a ~60-row covariance: agree to 1e-9.
        assert fast == pytest.approx(ref, rel=1e-9, abs=1e-9)
    outside = np.array([1.2, 0.5, 0.5, em.lam, 10.0])
    assert targets[0](outside) == -np.inf


class Stop(Exception):
    """Stands for a kill, raised from the progress callback."""


def _stop_after(iterations: int) -> Callable[[int], None]:
    def callback(done: int) -> None:
        if done >= iterations:
            raise Stop

    return callback


def test_serial_processes_and_vectorised_give_the_same_draws(
    small: tuple[Assembled, Emulator], tmp_path: Path
) -> None:
    a, em = small
    backends = ("serial", "processes", "vectorised", "vectorised-processes", "auto")
    runs = [
        calibrate(em, a, n_chains=4, n_burn=30, n_draws=20, seed=9, backend=b)  # type: ignore[arg-type]
        for b in backends
    ]
    np.testing.assert_array_equal(runs[0].draws, runs[1].draws)
    # Lockstep chains (all in one group, or one group per worker; "auto" is one of
    # these here): the batched likelihood equals the scalar one to rounding, so the
    # accept/reject decisions, and with them the draws, are the same.
    for run in runs[2:]:
        np.testing.assert_array_equal(runs[0].draws, run.draws)
        np.testing.assert_allclose(runs[0].log_density, run.log_density, rtol=1e-12)
    assert runs[0].draws.shape == (4, 20, 3)
    # Lockstep chains checkpoint too: killed after 37 of 50 sweeps (a snapshot after
    # the first batch of 25), they resume to the same draws.
    common = dict(n_chains=4, n_burn=30, n_draws=20, seed=9, backend="vectorised")
    with pytest.raises(Stop):
        calibrate(em, a, **common, checkpoint_dir=tmp_path, checkpoint_seconds=0.0,  # type: ignore[arg-type]
                  callback=_stop_after(4 * 37))  # fmt: skip
    assert (tmp_path / "lockstep.npz").is_file()
    resumed = calibrate(em, a, **common, checkpoint_dir=tmp_path, checkpoint_seconds=0.0)  # type: ignore[arg-type]
    np.testing.assert_array_equal(resumed.draws, runs[2].draws)


def test_short_chains_are_flagged(small: tuple[Assembled, Emulator]) -> None:
    a, em = small
    post = calibrate(em, a, n_chains=4, n_burn=10, n_draws=20, seed=1, backend="serial")
    assert not post.diagnostics.ok
    assert any("ESS" in w for w in post.warnings)


def test_failing_chains_are_extended_to_the_draws_of_longer_chains(
    small: tuple[Assembled, Emulator],
) -> None:
    a, em = small
    common = dict(n_chains=4, n_burn=30, seed=9, backend="vectorised")
    asked: list[tuple[int, int]] = []

    def on_extend(kept: int, longer: int) -> None:
        asked.append((kept, longer))

    # 4 x 50 draws cannot reach a bulk ESS of 400: extended by half at a time,
    # 50 -> 75 -> 100 (the most), still flagged at the end.
    grown = calibrate(em, a, n_draws=50, max_draws=100, on_extend=on_extend, **common)  # type: ignore[arg-type]
    assert asked == [(50, 75), (75, 100)]
    assert grown.draws.shape == (4, 100, 3)
    assert not grown.diagnostics.ok
    # Every kept length fills whole batches of 25, so the extended chains are those of
    # one run of 100 draws, bit for bit: the extensions continued, nothing was redone.
    direct = calibrate(em, a, n_draws=100, **common)  # type: ignore[arg-type]
    np.testing.assert_array_equal(grown.draws, direct.draws)
    np.testing.assert_array_equal(grown.log_density, direct.log_density)
    # Chains that pass are not extended.
    asked.clear()
    passed = calibrate(em, a, n_chains=4, n_burn=500, n_draws=1000, seed=9, max_draws=4000,
                       on_extend=on_extend, backend="vectorised")  # fmt: skip
    assert passed.diagnostics.ok, passed.warnings
    assert asked == []
    assert passed.draws.shape == (4, 1000, 3)
    with pytest.raises(ConfigError, match="max_draws must be >= n_draws = 50, got 40"):
        calibrate(em, a, n_draws=50, max_draws=40, **common)  # type: ignore[arg-type]


def test_a_calibration_killed_while_extending_resumes_at_that_length(
    small: tuple[Assembled, Emulator], tmp_path: Path
) -> None:
    a, em = small
    common = dict(n_chains=4, n_burn=30, n_draws=50, max_draws=100, seed=9, backend="vectorised",
                  checkpoint_dir=tmp_path, checkpoint_seconds=0.0)  # fmt: skip
    reference = calibrate(em, a, **{**common, "checkpoint_dir": tmp_path / "whole"})  # type: ignore[arg-type]
    asked: list[tuple[int, int]] = []

    def dies_in_the_last_round(kept: int, longer: int) -> Callable[[int], None] | None:
        asked.append((kept, longer))
        return _stop_after(4 * (30 + 90)) if longer == 100 else None

    with pytest.raises(Stop):
        calibrate(em, a, on_extend=dies_in_the_last_round, **common)  # type: ignore[arg-type]
    assert asked == [(50, 75), (75, 100)]
    asked.clear()
    resumed = calibrate(em, a, on_extend=dies_in_the_last_round, **common)  # type: ignore[arg-type]
    assert asked == []  # straight to 100 draws from the snapshots, no round repeated
    np.testing.assert_array_equal(resumed.draws, reference.draws)


def test_priors_must_keep_the_design_bounds(small: tuple[Assembled, Emulator]) -> None:
    a, em = small
    bad = dict(a.priors)
    bad["k_cb"] = UniformPrior(0.05, 0.2)
    with pytest.raises(ConfigError, match=r"bounds \[0.05, 0.2\], the design was drawn on"):
        calibrate(em, a, bad, n_chains=4, n_burn=10, n_draws=10, backend="serial")
    beta = dict(a.priors)
    beta["cp_fb"] = BetaPrior(672.0, 1008.0, 1.0, 2.0)  # the paper's later Beta(1, 2)
    post = calibrate(em, a, beta, n_chains=4, n_burn=10, n_draws=10, backend="serial")
    assert post.priors["cp_fb"] == beta["cp_fb"]


@pytest.fixture(scope="module")
def paper(
    paper_wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> tuple[VirtualExperiment, Posterior]:
    ve, a, em = paper_wall  # _fit(seed=0) trained with n_burn=400, n_draws=100, seed=1
    post = calibrate(em, a, n_chains=4, n_burn=1000, n_draws=1500, seed=3, backend="processes")
    return ve, post


def test_virtual_wall_intervals_cover_the_truth(paper: tuple[VirtualExperiment, Posterior]) -> None:
    ve, post = paper
    lower, upper = post.interval(0.95)
    for k, name in enumerate(post.names):
        assert lower[k] <= ve.truth[name] <= upper[k], name


def test_concrete_is_identified_and_the_boards_are_not(
    paper: tuple[VirtualExperiment, Posterior],
) -> None:
    _, post = paper
    sd = post.draws.reshape(-1, 3).std(axis=0)
    ratio = {n: sd[k] / _prior_sd(n) for k, n in enumerate(post.names)}
    # Paper's Table 3: k_CB and cp_CB within a few % of their prior ranges; cp_FB
    # spread over its interval. Thresholds 0.1 and 0.3 separate the two cases.
    assert ratio["k_cb"] < 0.1
    assert ratio["cp_cb"] < 0.1
    assert ratio["cp_fb"] > 0.3


def test_diagnostics_pass_and_inference_data_is_physical(
    paper: tuple[VirtualExperiment, Posterior],
) -> None:
    _, post = paper
    assert post.warnings == (), post.warnings
    assert np.all(post.diagnostics.rhat <= 1.01)
    assert np.all(post.diagnostics.ess_bulk[:3] >= 400)
    idata = post.inference_data()
    assert set(idata.posterior.data_vars) == {*NAMES, "lambda", "lambda_star"}
    np.testing.assert_array_equal(idata.posterior["cp_cb"].values, post.draws[..., 1])
    assert 640.0 <= float(idata.posterior["cp_cb"].min()) <= 960.0
    table = post.summary()
    assert list(table.index) == [*NAMES, "lambda", "lambda_star"]


@pytest.mark.slow
def test_coverage_over_ten_truths() -> None:
    rng = np.random.default_rng(2024)
    hits = dict.fromkeys(NAMES, 0)
    n_cases = 10
    for case in range(n_cases):
        truth = random_truth(rng)
        _, a = _fit(seed=100 + case, truth=truth)
        em = train(a, n_burn=400, n_draws=100, n_chains=1, seed=case)
        post = calibrate(em, a, n_chains=4, n_burn=400, n_draws=600, seed=case)
        lower, upper = post.interval(0.95)
        for k, name in enumerate(NAMES):
            hits[name] += int(lower[k] <= truth[name] <= upper[k])
    # With exact 95 % intervals, 8 or more hits in 10 has probability 0.99 per parameter.
    assert all(h >= 8 for h in hits.values()), hits
