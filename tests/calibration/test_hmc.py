"""NUTS for the calibration posterior (bayescal.calibration.hmc, the extra bayescal[hmc])."""

from __future__ import annotations

import copy
import multiprocessing
import sys
import tomllib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from bayescal.calibration import hmc
from bayescal.calibration.kron import Kind, make_algebra
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.calibration.target import CalibrationPosterior
from bayescal.config import CalibrationSection, study_from_dict
from bayescal.config import study as study_config
from bayescal.design import BetaPrior
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.errors import ConfigError
from bayescal.mcmc import nuts
from bayescal.optional import module_installed
from bayescal.pipeline import stages
from paths import FIXTURES
from virtual_wall import VirtualExperiment

HAS_JAX = all(module_installed(m) for m in ("jax", "blackjax"))
needs_jax = pytest.mark.skipif(not HAS_JAX, reason="the extra bayescal[hmc] is not installed")
FIXTURE = FIXTURES / "wall-study"
BASE = tomllib.loads((FIXTURE / "study.toml").read_text(encoding="utf-8"))


def _jax() -> Any:
    jax, _ = hmc.require_jax()
    return jax


@pytest.fixture(scope="module")
def wall(
    paper_wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> tuple[VirtualExperiment, Assembled, Emulator]:
    """The paper-size virtual wall (R = 30 x m* = 25) of tests/conftest.py."""
    return paper_wall


def _target(
    a: Assembled,
    em: Emulator,
    beta: bool = False,
    order: np.ndarray | None = None,
    algebra: Kind = "kronecker",
    w_star: np.ndarray | None = None,
) -> CalibrationPosterior:
    """The wall's calibration target; with ``order``, its periods are observed in that
    (shuffled) order: ``obs_index = order`` and the rows of ``w*`` (default
    ``a.w_star[order]``) listed with it."""
    priors = list(a.priors.values())
    if beta:  # the paper's later Beta(1, 2) on cp_fb, and a Beta(2, 3) on k_cb
        priors[2] = BetaPrior(priors[2].lower, priors[2].upper, 1.0, 2.0)
        priors[0] = BetaPrior(priors[0].lower, priors[0].upper, 2.0, 3.0)
    if w_star is None:
        w_star = a.w_star if order is None else a.w_star[order]
    alg = make_algebra(algebra, em.theta, em.x, em.kernels, em.basis.ktk, em.w, w_star, order)
    return CalibrationPosterior(alg, priors, em.lam_prior, a.lam_star_prior)


def _shuffled_periods(em: Emulator) -> np.ndarray:
    """A permutation of the wall's periods that is not sorted (an unsorted ``obs_index``)."""
    order = np.random.default_rng(7).permutation(em.x.shape[0])
    assert not np.all(np.diff(order) > 0)
    return order


def _points(em: Emulator, a: Assembled, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lam_star = a.lam_star_prior[0] / a.lam_star_prior[1]
    return np.column_stack(
        [
            rng.uniform(0.02, 0.98, (n, 3)),
            em.lam * rng.uniform(0.3, 3.0, n),
            lam_star * rng.uniform(0.3, 3.0, n),
        ]
    )


GAUSS_MEAN = np.array([1.0, -2.0, 0.5])
GAUSS_SD = np.array([1.0, 0.1, 3.0])
GAUSS_CORR = np.array([[1.0, 0.8, 0.0], [0.8, 1.0, -0.4], [0.0, -0.4, 1.0]])
FD_STEP = 1e-3


def _fourth_order_fd(f: Any, z: np.ndarray, h: float) -> np.ndarray:
    out = np.empty(z.size)
    for k in range(z.size):
        e = np.zeros(z.size)
        e[k] = h
        out[k] = (
            -float(f(z + 2 * e)) + 8 * float(f(z + e)) - 8 * float(f(z - e)) + float(f(z - 2 * e))
        ) / (12 * h)
    return out


def _jax_side(targets: list[CalibrationPosterior], points: np.ndarray) -> dict[str, Any]:
    """Everything that runs JAX, evaluated in a spawned child (see the ``jax_side`` fixture)."""
    jax = _jax()
    out: dict[str, Any] = {}
    for b, target in enumerate(targets):
        con, unc = hmc.jax_log_posterior(hmc.jax_arrays(target.grid(), target.prior_terms))
        f_v, f_z = jax.jit(con), jax.jit(unc)
        z = hmc.to_unconstrained(points, 3)
        out[f"v{b}"] = np.array([float(f_v(v)) for v in points])
        out[f"z{b}"] = np.array([float(f_z(x)) for x in z]) - hmc.log_jacobian(z, 3)
        out[f"outside{b}"] = float(f_v(np.array([1.2, 0.5, 0.5, 100.0, 10.0])))
        out[f"grad{b}"] = np.stack([np.asarray(jax.jit(jax.grad(unc))(x)) for x in z[:3]])
        out[f"fd{b}"] = np.stack([_fourth_order_fd(f_z, x, FD_STEP) for x in z[:3]])
    return out


def _gaussian_runs() -> tuple[nuts.NutsChains, nuts.NutsChains, nuts.NutsChains, list[int]]:
    """Two NUTS runs with one seed on a correlated Gaussian, and one with the chains
    vmapped into one program (in a spawned child), with the vmapped run's progress."""
    jax = _jax()
    prec = jax.numpy.asarray(np.linalg.inv(GAUSS_CORR * np.outer(GAUSS_SD, GAUSS_SD)))

    def logdensity(x: Any) -> Any:
        r = x - GAUSS_MEAN
        return -0.5 * r @ prec @ r

    starts = np.random.default_rng(0).normal(size=(4, 3)) * 3.0
    run = nuts.run_nuts(logdensity, starts, 400, 1000, seed=11)
    ticks: list[int] = []
    vmapped = nuts.run_nuts(logdensity, starts, 400, 1000, seed=11, vectorised=True,
                            callback=ticks.append)  # fmt: skip
    return run, nuts.run_nuts(logdensity, starts, 400, 1000, seed=11), vmapped, ticks


def _in_child(fn: Any, *args: Any) -> Any:
    """Run ``fn`` in a spawned process: once JAX has started in the pytest process,
    every later fork (process pools of other tests) would warn, i.e. fail."""
    with ProcessPoolExecutor(1, multiprocessing.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


@pytest.fixture(scope="module")
def jax_side(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> tuple[list[CalibrationPosterior], np.ndarray, dict[str, Any]]:
    """The JAX log posteriors at random points, evaluated in a spawned process."""
    if not HAS_JAX:
        pytest.skip("the extra bayescal[hmc] is not installed")
    _, a, em = wall
    targets = [
        _target(a, em, beta=False),
        _target(a, em, beta=True),
        _target(a, em, order=_shuffled_periods(em)),  # PERMUTED
    ]
    points = _points(em, a, 8, seed=0)
    return targets, points, _in_child(_jax_side, targets, points)


PERMUTED = 2  # jax_side's third target: the periods observed in a shuffled order


@pytest.mark.parametrize("beta", [0, 1, PERMUTED])
def test_jax_log_posterior_equals_the_numpy_one(
    jax_side: tuple[list[CalibrationPosterior], np.ndarray, dict[str, Any]], beta: int
) -> None:
    targets, points, out = jax_side
    ref = np.array([targets[beta](v) for v in points])
    # Same algebra in another order of summation (einsum vs matmul): rounding is
    # relative to the size of the pieces (log |Omega| and the quadratic form, ~1e5,
    # which cancel in the Schur complement), not to their sum: 1e-10 of that size.
    scale = np.array(
        [
            abs(pc.logdet) + abs(pc.quad) + pc.size * np.log(2.0 * np.pi)
            for pc in (targets[beta].algebra.pieces(v[:3], v[3], v[4]) for v in points)
        ]
    )
    for side in ("v", "z"):
        np.testing.assert_array_less(np.abs(out[f"{side}{beta}"] - ref), 1e-10 * scale)
    assert targets[beta](np.array([1.2, 0.5, 0.5, 100.0, 10.0])) == -np.inf
    assert out[f"outside{beta}"] == -np.inf


def test_a_permuted_obs_index_gives_one_density_on_every_route(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
    jax_side: tuple[list[CalibrationPosterior], np.ndarray, dict[str, Any]],
) -> None:
    """``obs_index`` in a shuffled order, ``w*`` listed with it: the same data as the
    sorted study, so the JAX route (``StackedGrid.obs_rot``), the numpy Kronecker
    route and the dense reference all give the sorted study's density."""
    _, a, em = wall
    targets, points, out = jax_side
    sorted_target, permuted = targets[0], targets[PERMUTED]
    order = permuted.algebra.data.obs_index
    assert not np.array_equal(order, np.sort(order))
    dense = _target(a, em, order=order, algebra="dense")
    kron = np.array([permuted(v) for v in points])
    # The observed weights land on the same periods: the numpy route is bit-identical.
    np.testing.assert_array_equal(kron, [sorted_target(v) for v in points])
    np.testing.assert_array_equal(permuted.grid().obs_rot, sorted_target.grid().obs_rot)
    # Against the dense Cholesky reference (rows of w* in the order of obs_index) and
    # the JAX route: rounding relative to the pieces (log |Omega|, the quadratic form),
    # as in test_jax_log_posterior_equals_the_numpy_one; dense vs Kronecker reached
    # 1.3e-10 of that size on these points, 1e-9 leaves a factor 8.
    scale = np.array(
        [
            abs(pc.logdet) + abs(pc.quad) + pc.size * np.log(2.0 * np.pi)
            for pc in (permuted.algebra.pieces(v[:3], v[3], v[4]) for v in points)
        ]
    )
    np.testing.assert_array_less(np.abs(np.array([dense(v) for v in points]) - kron), 1e-9 * scale)
    for side in ("v", "z"):
        np.testing.assert_array_less(np.abs(out[f"{side}{PERMUTED}"] - kron), 1e-10 * scale)
    # The test can fail: observations put on the wrong periods (obs_index shuffled,
    # w* not) change the density by far more than the tolerance.
    wrong = _target(a, em, order=order, w_star=a.w_star)
    assert np.all(np.abs(np.array([wrong(v) for v in points]) - kron) > 1e3 * 1e-9 * scale)


@pytest.mark.parametrize("beta", [0, 1])
def test_gradient_matches_finite_differences(
    jax_side: tuple[list[CalibrationPosterior], np.ndarray, dict[str, Any]], beta: int
) -> None:
    g, fd = jax_side[2][f"grad{beta}"], jax_side[2][f"fd{beta}"]
    # Fourth-order central differences with h = 1e-3: truncation ~h^4 f^(5) ~ 1e-12
    # f^(5); rounding ~eps_f / h, where the log posterior is computed to ~1e-10 of
    # its pieces (log |Omega| and the quadratic form, ~1e5, which cancel): ~6e-6 /
    # h = 6e-3 (with h = 1e-4 and the MAP-trained emulator it reached 0.05, the
    # test's whole tolerance; with h = 2e-5, 0.3). Gradients reach ~1e4, so both
    # stay below 1e-6 of the largest component.
    for row_g, row_fd in zip(g, fd, strict=True):
        np.testing.assert_allclose(row_g, row_fd, rtol=1e-6, atol=1e-6 * np.abs(row_g).max())


@needs_jax
@pytest.mark.slow
def test_nuts_recovers_a_correlated_gaussian() -> None:
    run, again, vmapped, ticks = _in_child(_gaussian_runs)
    np.testing.assert_array_equal(run.position, again.position)  # seeded: reproducible
    # The vmapped program (one compiled program for all chains) samples the same target.
    for chains in (run, vmapped):
        flat = chains.position.reshape(-1, 3)
        ess = 1000.0  # conservative: NUTS gives ~1 effective draw per draw on a Gaussian
        # Means within 4.5 Monte Carlo standard errors (sd / sqrt(ESS)): a false
        # alarm has probability ~1e-5 per coordinate.
        err = np.abs(flat.mean(axis=0) - GAUSS_MEAN)
        np.testing.assert_array_less(err, 4.5 * GAUSS_SD / np.sqrt(ess))
        # The SD's Monte Carlo error is ~sd / sqrt(2 ESS) = 2.2 % of it; allow 10 %.
        np.testing.assert_allclose(flat.std(axis=0), GAUSS_SD, rtol=0.10)
        # The correlation's standard error is ~(1 - r^2) / sqrt(ESS) <= 0.032; allow 0.1.
        np.testing.assert_allclose(np.corrcoef(flat.T), GAUSS_CORR, atol=0.1)
        assert chains.divergent.sum() == 0
        assert np.all((chains.acceptance > 0.6) & (chains.acceptance < 0.99))  # towards 0.8
    # vmapped progress: after the warm-up of all chains, then after each of the 10 chunks
    assert ticks == [4 * 400 + 4 * 100 * k for k in range(11)]


@dataclass(frozen=True)
class Both:
    """NUTS and MwG calibrations of the same virtual wall."""

    ve: VirtualExperiment
    target: CalibrationPosterior
    nuts: Posterior
    mwg: Posterior
    ticks: list[int]


@pytest.fixture(scope="module")
def both(wall: tuple[VirtualExperiment, Assembled, Emulator]) -> Both:
    ve, a, em = wall
    ticks: list[int] = []
    nuts = calibrate(em, a, n_burn=300, n_draws=600, seed=3, sampler="nuts", callback=ticks.append)
    mwg = calibrate(em, a, n_burn=1000, n_draws=1500, seed=3, backend="processes")
    return Both(ve, _target(a, em), nuts, mwg, ticks)


@needs_jax
@pytest.mark.slow
def test_calibrate_with_nuts_returns_a_full_posterior(both: Both) -> None:
    nuts = both.nuts
    assert nuts.unit_draws.shape == (4, 600, 3)
    assert nuts.lam.shape == nuts.lam_star.shape == nuts.log_density.shape == (4, 600)
    assert nuts.acceptance.shape == (4, 5)
    assert np.all((nuts.acceptance > 0.5) & (nuts.acceptance <= 1.0))
    assert nuts.warnings == (), nuts.warnings
    # Progress from the spawned child: each chain after its warm-up and after each of
    # its 10 chunks of 60 draws, all relayed before calibrate returns.
    per_chain = [c * 900 + 300 + 60 * k for c in range(4) for k in range(11)]
    assert both.ticks == per_chain
    # The stored log-density is the numpy posterior at the draws (Jacobian removed);
    # 1e-10 as in test_jax_log_posterior_equals_the_numpy_one.
    v = np.concatenate([nuts.unit_draws[1, 7], [nuts.lam[1, 7], nuts.lam_star[1, 7]]])
    assert nuts.log_density[1, 7] == pytest.approx(both.target(v), rel=1e-10)


@needs_jax
@pytest.mark.slow
def test_nuts_and_mwg_agree_and_cover_the_truth(both: Both) -> None:
    dn, dm = both.nuts.diagnostics, both.mwg.diagnostics
    for k, name in enumerate(both.nuts.names):
        se = np.hypot(dn.mcse_mean[k], dm.mcse_mean[k])
        # Two independent estimates of the same mean: 5 combined MCSE (p ~ 6e-7).
        assert abs(dn.mean[k] - dm.mean[k]) <= 5.0 * se, name
        se_sd = np.hypot(dn.mcse_sd[k], dm.mcse_sd[k])
        assert abs(dn.sd[k] - dm.sd[k]) <= 5.0 * se_sd, name
    lower, upper = both.nuts.interval(0.95)
    for k, name in enumerate(both.nuts.names):
        assert lower[k] <= both.ve.truth[name] <= upper[k], name


def test_missing_extra_is_a_one_line_config_error(
    wall: tuple[VirtualExperiment, Assembled, Emulator], monkeypatch: pytest.MonkeyPatch
) -> None:
    _, a, em = wall
    monkeypatch.setitem(sys.modules, "blackjax", None)  # import blackjax -> ImportError
    with pytest.raises(ConfigError, match=r'pip install "bayescal\[hmc\]"') as info:
        calibrate(em, a, n_burn=10, n_draws=10, sampler="nuts")
    assert "\n" not in str(info.value)
    assert "sampler 'nuts' needs JAX and BlackJAX" in str(info.value)


@needs_jax
def test_nuts_needs_the_kronecker_algebra_and_a_warm_up(
    wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> None:
    _, a, em = wall
    with pytest.raises(ConfigError, match=r"got algebra 'dense'"):
        calibrate(em, a, n_burn=100, n_draws=10, sampler="nuts", algebra="dense")
    with pytest.raises(ConfigError, match=r"got 0 iterations, expected at least 20"):
        calibrate(em, a, n_burn=0, n_draws=10, sampler="nuts")


def test_study_with_nuts_but_without_the_extra_fails_at_load(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Checked when the study is read (bayescal validate, before any stage runs),
    # not after the simulations and the emulator training.
    monkeypatch.setitem(sys.modules, "blackjax", None)  # find_spec -> ValueError
    raw = copy.deepcopy(BASE)
    raw.setdefault("calibration", {})["sampler"] = "nuts"
    with pytest.raises(ConfigError, match=r"'nuts' needs blackjax, which is not installed") as info:
        study_from_dict(raw, root=FIXTURE)
    assert 'pip install "bayescal[hmc]"' in str(info.value)
    assert "\n" not in str(info.value)


def test_sampler_option_round_trips_and_is_checked(monkeypatch: pytest.MonkeyPatch) -> None:
    # with or without JAX
    monkeypatch.setattr(study_config, "module_installed", lambda module: True)
    assert CalibrationSection().sampler == "mwg"
    raw = copy.deepcopy(BASE)
    raw.setdefault("calibration", {})["sampler"] = "nuts"
    study = study_from_dict(raw, root=FIXTURE)
    assert study.calibration.sampler == "nuts"
    dumped = study.model_dump(mode="json")
    assert dumped["calibration"]["sampler"] == "nuts"
    assert CalibrationSection.model_validate(dumped["calibration"]) == study.calibration
    raw["calibration"]["sampler"] = "hmc"
    with pytest.raises(ConfigError, match=r"calibration\.sampler: .*'mwg' or 'nuts'"):
        study_from_dict(raw, root=FIXTURE)


def test_pipeline_stage_passes_the_sampler(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(study_config, "module_installed", lambda module: True)
    raw = copy.deepcopy(BASE)
    raw.setdefault("calibration", {})["sampler"] = "nuts"
    study = study_from_dict(raw, root=FIXTURE)
    seen: dict[str, Any] = {}
    fake = SimpleNamespace(with_derived=lambda derived: derived)

    def record(*args: Any, **kw: Any) -> SimpleNamespace:
        seen.update(kw)
        return fake

    monkeypatch.setattr(stages, "calibrate", record)
    monkeypatch.setattr(stages, "derived_draws", lambda ctx, post: {})
    ctx = SimpleNamespace(study=study, options=stages.Options(), seed=lambda *args: 0, held={})
    em = SimpleNamespace(emulator=None, assembled=SimpleNamespace(observations=None))
    stages.calibrate_stage(ctx, em)  # type: ignore[arg-type]
    assert seen["sampler"] == "nuts"


def test_sampler_warnings_are_appended_to_the_diagnostics() -> None:
    rng = np.random.default_rng(0)
    priors = {"a": BetaPrior(0.0, 1.0, 2.0, 2.0)}
    common = dict(
        names=["a"],
        priors=priors,
        unit_draws=rng.uniform(0.2, 0.8, (4, 50, 1)),
        lam=rng.uniform(1.0, 2.0, (4, 50)),
        lam_star=rng.uniform(1.0, 2.0, (4, 50)),
        log_density=rng.normal(size=(4, 50)),
        acceptance=np.full((4, 3), 0.9),
        seed=0,
        algebra="kronecker",
    )
    plain = Posterior.build(**common)  # type: ignore[arg-type]
    flagged = Posterior.build(**common, sampler_warnings=["chain 3 had 2 divergent"])  # type: ignore[arg-type]
    assert flagged.warnings == (*plain.warnings, "chain 3 had 2 divergent")
