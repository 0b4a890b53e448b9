"""Emulator MAP by gradient search: exact gradient, multi-start search, Laplace, same quality."""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest

from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.gradient import LogScalePosterior
from bayescal.emulator.mapfit import (
    MapSettings,
    distinct_best,
    find_map,
    laplace_covariance,
    laplace_draws,
    laplace_hessian,
    structured_starts,
)
from bayescal.emulator.training import TrainingPosterior, train
from bayescal.errors import ConfigError
from virtual_wall import VirtualExperiment

LAM_PRIOR = (300.0, 40.0)


def _small(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    theta, x = rng.random((7, 2)), rng.random((5, 3))
    w = rng.normal(size=(35, 2))
    return theta, x, w, np.array([20.0, 3.0])


def _point(post: LogScalePosterior, rng: np.random.Generator) -> np.ndarray:
    layout = post.layout
    return np.log(
        layout.pack(
            rng.uniform(0.1, 4.0, (layout.p, layout.r)),
            rng.uniform(0.5, 2.0, layout.p),
            rng.uniform(5.0, 10.0),
        )
    )


def test_value_is_the_training_posterior_on_the_log_scale() -> None:
    theta, x, w, ktk = _small(0)
    post = LogScalePosterior(theta, x, w, ktk, LAM_PRIOR)
    ref = TrainingPosterior(theta, x, w, ktk, LAM_PRIOR)
    rng = np.random.default_rng(1)
    for _ in range(4):
        u = _point(post, rng)
        expected = ref(np.exp(u)) + float(np.sum(u))
        # Same eigen-decompositions and sums, grouped differently: rounding only.
        assert post.value(u) == pytest.approx(expected, rel=1e-13)
        assert post.value_and_grad(u)[0] == pytest.approx(expected, rel=1e-13)


def test_gradient_equals_central_differences() -> None:
    theta, x, w, ktk = _small(2)
    post = LogScalePosterior(theta, x, w, ktk, LAM_PRIOR)
    rng = np.random.default_rng(3)
    for _ in range(3):
        u = _point(post, rng)
        _, grad = post.value_and_grad(u)
        h = 1e-6
        fd = np.array(
            [(post.value(u + h * e) - post.value(u - h * e)) / (2 * h) for e in np.eye(u.size)]
        )
        # Central differences of a sum of O(100) terms: error ~ eps |f| / h + h^2 f''' ~ 1e-7.
        np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6)


def test_subset_equals_a_posterior_built_from_the_subset() -> None:
    theta, x, w, ktk = _small(4)
    post = LogScalePosterior(theta, x, w, ktk, LAM_PRIOR)
    runs = np.array([0, 2, 3, 6])
    rows = (runs[:, None] * x.shape[0] + np.arange(x.shape[0])).reshape(-1)
    direct = LogScalePosterior(theta[runs], x, w[rows], ktk, LAM_PRIOR)
    u = _point(post, np.random.default_rng(5))
    assert post.subset(runs).value(u) == direct.value(u)


def test_laplace_hessian_equals_differences_of_the_full_gradient() -> None:
    theta, x, w, ktk = _small(6)
    post = LogScalePosterior(theta, x, w, ktk, LAM_PRIOR)
    u = _point(post, np.random.default_rng(7))
    hess = laplace_hessian(post, u)
    h = 1e-5
    ref = np.column_stack(
        [
            -(post.value_and_grad(u + h * e)[1] - post.value_and_grad(u - h * e)[1]) / (2 * h)
            for e in np.eye(u.size)
        ]
    )
    np.testing.assert_allclose(hess, 0.5 * (ref + ref.T), rtol=1e-5, atol=1e-4)
    # Bases are independent given lambda: blocks of different bases do not mix.
    layout = post.layout
    assert np.all(hess[layout.block(0), layout.block(1)] == 0.0)


def test_laplace_draws_have_the_covariance() -> None:
    cov = np.array([[2.0, 0.6], [0.6, 0.5]])
    draws = laplace_draws(np.array([0.5, -1.0]), cov, 40000, np.random.default_rng(8))
    logs = np.log(draws)
    # 40 000 draws: the sample covariance is within ~3 % (a few standard errors).
    np.testing.assert_allclose(np.cov(logs.T), cov, rtol=0.05, atol=0.02)
    flat = laplace_covariance(np.diag([4.0, 0.0]))
    assert flat[0, 0] == pytest.approx(0.25)
    assert flat[1, 1] == pytest.approx(1.0)


def test_structured_starts_and_distinct_optima() -> None:
    starts = structured_starts(3)
    assert len(starts) == 4
    assert np.all(starts[0] == 0.0)
    assert [int(np.argmax(s)) for s in starts[1:]] == [0, 1, 2]
    cfg = MapSettings(tol=0.01)
    found = [(10.0, np.zeros(2)), (9.995, np.ones(2)), (8.0, np.ones(2)), (3.0, np.ones(2))]
    assert [v for v, _ in distinct_best(found, 2, cfg)] == [10.0, 8.0]
    with pytest.raises(ConfigError, match="confirmations"):
        MapSettings(confirmations=0)


def test_the_map_search_finds_the_best_optimum_and_the_subset_route_agrees() -> None:
    theta, x, w, ktk = _small(9)
    post = LogScalePosterior(theta, x, w, ktk, LAM_PRIOR)
    full = find_map(post, seed=1)
    # The gradient vanishes at the MAP (up to the L-BFGS-B tolerance).
    _, grad = post.value_and_grad(full.u)
    assert np.max(np.abs(grad)) < 1e-2
    assert full.value >= full.value_start
    # No start of 40 random ones, each polished, reaches a higher optimum.
    rng = np.random.default_rng(10)
    cfg = MapSettings(max_starts=1)
    for _ in range(8):
        other = find_map(post, seed=int(rng.integers(1 << 30)), settings=cfg)
        assert other.value <= full.value + 1e-6
    # Starts on 5 of the 7 runs, candidates polished on all: the same optimum here.
    sub = find_map(post, seed=1, settings=MapSettings(explore_runs=5))
    assert sub.value == pytest.approx(full.value, abs=1e-3)
    assert all(len(s.polished) >= 1 for s in sub.searches)


def test_a_warm_search_from_the_map_returns_it_with_two_starts_per_basis() -> None:
    """Warm starts at the full search's optima: the same MAP, two starts per basis on
    all runs instead of the multi-start search; a warm block for the first basis only
    leaves the others to the full search; a block of the wrong length is an error."""
    theta, x, w, ktk = _small(9)
    post = LogScalePosterior(theta, x, w, ktk, LAM_PRIOR)
    full = find_map(post, seed=1)
    blocks = [s.u for s in full.searches]
    warm = find_map(post, seed=1, warm=blocks)
    assert warm.value == pytest.approx(full.value, abs=1e-6)
    assert [len(s.optima) for s in warm.searches] == [2, 2]
    assert sum(s.evaluations[1] for s in warm.searches) < sum(
        sum(s.evaluations) for s in full.searches
    )
    # From a poor start (every beta 1e-3) the neutral start still finds the optimum.
    poor = [np.full_like(b, math.log(1e-3)) for b in blocks]
    assert find_map(post, seed=1, warm=poor).value >= full.value - 0.05
    half = find_map(post, seed=1, warm=blocks[:1])
    assert len(half.searches[0].optima) == 2
    assert len(half.searches[1].optima) > 2
    with pytest.raises(ValueError, match="blocks of length r \\+ 1"):
        find_map(post, warm=[blocks[0][:-1]])


def test_train_warm_from_itself_keeps_its_map_and_ignores_other_inputs(
    small: Assembled,
) -> None:
    """``train(warm=...)``: from the emulator's own MAP the same MAP (to the search's
    tolerance); an emulator of other inputs is ignored (the full search)."""
    cold = train(small, method="map", seed=4, n_draws=10)
    again = train(small, method="map", seed=4, n_draws=10, warm=cold)
    assert again.log_post_map == pytest.approx(cold.log_post_map, abs=0.01)
    other = dataclasses.replace(cold, input_labels=(*cold.input_labels[:-1], "other"))
    ignored = train(small, method="map", seed=4, n_draws=10, warm=other)
    assert ignored.log_post_map == cold.log_post_map


@pytest.fixture(scope="module")
def small(
    small_wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> Assembled:
    return small_wall[1]


@pytest.mark.slow
def test_train_map_and_mcmc_reach_the_same_map_and_cv(small: Assembled) -> None:
    """Equal quality at a small size: the MAP route against the paper's MCMC route."""
    mcmc = train(small, method="mcmc", n_burn=500, n_draws=1000, n_chains=2, seed=3)
    fast = train(small, method="map", seed=3)
    # The MCMC's best draw refined is a local search too: the gradient route is at
    # least as high (to the refinement's tolerance) ...
    assert fast.log_post_map >= mcmc.log_post_map - 0.05
    # ... and the emulators predict alike: leave-one-run-out RMSE within 1 %.
    rmse_fast = fast.loo_cv().rmse["heat_flux_in"]
    rmse_mcmc = mcmc.loo_cv().rmse["heat_flux_in"]
    assert rmse_fast == pytest.approx(rmse_mcmc, rel=0.01)
    assert fast.hyper_draws.shape == (1, 1000, fast.layout.d)
    assert np.all(np.isnan(fast.hyper_lp))
    assert np.all(np.isnan(fast.hyper_acceptance))
    assert np.all(np.isfinite(fast.hyper_draws))


def test_train_map_is_the_same_in_processes(small: Assembled) -> None:
    serial = train(small, method="map", seed=4, n_draws=10)
    parallel = train(small, method="map", seed=4, n_draws=10, backend="processes")
    # The same searches; LAPACK may round differently in another process (memory
    # alignment), so the optimiser's path may differ in the last bits.
    assert serial.log_post_map == pytest.approx(parallel.log_post_map, rel=1e-10)
    np.testing.assert_allclose(serial.beta, parallel.beta, rtol=1e-4)


def test_train_rejects_an_unknown_method(small: Assembled) -> None:
    with pytest.raises(ConfigError, match="training method must be one of"):
        train(small, method="nuts")  # type: ignore[arg-type]


def test_log_scale_posterior_pickles_without_its_memos() -> None:
    theta, x, w, ktk = _small(11)
    post = LogScalePosterior(theta, x, w, ktk, LAM_PRIOR)
    u = _point(post, np.random.default_rng(12))
    value = post.value(u)
    back = pickle.loads(pickle.dumps(post))
    assert back.evaluations == 0
    assert back.value(u) == pytest.approx(value, rel=1e-14)
    assert math.isfinite(value)
