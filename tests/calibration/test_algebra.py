"""Fast Kronecker likelihoods against the dense Cholesky reference.

Tolerance: the two back ends compute the same numbers by different
factorisations, so they agree to roughly ``eps * cond(Omega)``. The problems
drawn here keep the nuggets ``a = (lambda k^T k)^-1`` above ~1e-4 and the
covariance below ~10 on the diagonal, so ``cond(Omega)`` stays below ~1e6 and
the worst disagreement seen in 2000 random draws was 2e-11; 1e-9 leaves a
factor 50. The log-determinant can be close to zero (a sum of logs of both
signs), so differences are measured relative to ``max(|a|, |b|, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from bayescal.calibration.dense import DenseCalibrationDensity
from bayescal.calibration.kron import KronCalibrationDensity, make_algebra
from bayescal.emulator.dense import calibration_covariance, dense_logpdf, dense_training_logpdf
from bayescal.emulator.kernel import LogDensity, SeparableKernel
from bayescal.emulator.kron import kron_training_logpdf, training_logpdf

RTOL = 1e-9  # see the module docstring
FIELDS = ("logpdf", "logdet", "quad")


Args = tuple[
    np.ndarray,
    np.ndarray,
    list[SeparableKernel],
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray | None,
]


@dataclass(frozen=True)
class Problem:
    theta: np.ndarray
    x: np.ndarray
    kernels: list[SeparableKernel]
    ktk: np.ndarray
    w: np.ndarray
    w_star: np.ndarray
    theta_star: np.ndarray
    lam: float
    lam_star: float

    def args(self, obs: np.ndarray | None = None) -> Args:
        w_star = self.w_star if obs is None else self.w_star[obs]
        return (self.theta, self.x, self.kernels, self.ktk, self.w, w_star, obs)


def _log_uniform(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(np.log10(lo), np.log10(hi)).map(lambda e: float(10.0**e))


@st.composite
def problems(draw: st.DrawFn, max_bases: int = 3) -> Problem:
    n_runs = draw(st.integers(2, 8))
    n_per = draw(st.integers(1, 7))
    t = draw(st.integers(1, 3))
    s = draw(st.integers(1, 3))
    p = draw(st.integers(1, max_bases))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kernels = [
        SeparableKernel(rng.uniform(0.01, 0.99, t + s), draw(_log_uniform(0.1, 10.0)), t)
        for _ in range(p)
    ]
    return Problem(
        theta=rng.random((n_runs, t)),
        x=rng.random((n_per, s)),
        kernels=kernels,
        ktk=rng.uniform(1.0, 10.0, p),
        w=rng.normal(size=(n_runs * n_per, p)),
        w_star=rng.normal(size=(n_per, p)),
        theta_star=rng.random(t),
        lam=draw(_log_uniform(0.1, 1e3)),
        lam_star=draw(_log_uniform(1e-2, 1e3)),
    )


def _assert_agree(fast: LogDensity, ref: LogDensity) -> None:
    assert fast.size == ref.size
    for name in FIELDS:
        a, b = getattr(fast, name), getattr(ref, name)
        assert abs(a - b) <= RTOL * max(abs(a), abs(b), 1.0), (name, a, b)


@settings(max_examples=60, deadline=None)
@given(problems())
def test_full_grid_calibration_matches_dense(prob: Problem) -> None:
    ref = DenseCalibrationDensity(*prob.args()).pieces(prob.theta_star, prob.lam, prob.lam_star)
    for method in ("schur", "eigen"):
        fast = KronCalibrationDensity(*prob.args(), method=method)
        _assert_agree(fast.pieces(prob.theta_star, prob.lam, prob.lam_star), ref)


@settings(max_examples=60, deadline=None)
@given(problems(), st.data())
def test_missing_periods_and_per_period_nuggets_match_dense(
    prob: Problem, data: st.DataObject
) -> None:
    n_per = prob.x.shape[0]
    subset = data.draw(st.sets(st.integers(0, n_per - 1), min_size=1, max_size=n_per))
    obs = np.array(sorted(subset))
    lam_star = np.array(
        data.draw(st.lists(_log_uniform(1e-2, 1e3), min_size=obs.size, max_size=obs.size))
    )
    dense = DenseCalibrationDensity(*prob.args(obs))
    fast = KronCalibrationDensity(*prob.args(obs))
    for ls in (prob.lam_star, lam_star):
        _assert_agree(
            fast.pieces(prob.theta_star, prob.lam, ls), dense.pieces(prob.theta_star, prob.lam, ls)
        )


@settings(max_examples=60, deadline=None)
@given(problems(), st.data())
def test_an_unsorted_obs_index_matches_dense_and_the_sorted_one(
    prob: Problem, data: st.DataObject
) -> None:
    """Observed periods listed in any order (``w*`` rows with them): the same data, so
    the same density as the sorted listing, on the full grid and with missing periods."""
    n_per = prob.x.shape[0]
    subset = data.draw(st.sets(st.integers(0, n_per - 1), min_size=1, max_size=n_per))
    obs = np.array(data.draw(st.permutations(sorted(subset))))
    ordered = np.sort(obs)
    ref = DenseCalibrationDensity(*prob.args(obs)).pieces(prob.theta_star, prob.lam, prob.lam_star)
    methods = ("schur", "eigen") if obs.size == n_per else ("schur",)  # eigen: full grid
    for method in methods:
        fast = KronCalibrationDensity(*prob.args(obs), method=method)
        _assert_agree(fast.pieces(prob.theta_star, prob.lam, prob.lam_star), ref)
    sorted_ref = KronCalibrationDensity(*prob.args(ordered))
    _assert_agree(
        KronCalibrationDensity(*prob.args(obs)).pieces(prob.theta_star, prob.lam, prob.lam_star),
        sorted_ref.pieces(prob.theta_star, prob.lam, prob.lam_star),
    )


@settings(max_examples=40, deadline=None)
@given(problems(), st.integers(0, 2**32 - 1))
def test_per_basis_and_period_nuggets_match_dense(prob: Problem, seed: int) -> None:
    """The difference process's ``B_j``: one observation nugget per basis and period."""
    rng = np.random.default_rng(seed)
    p, n_per = len(prob.kernels), prob.x.shape[0]
    a = rng.uniform(1e-3, 1.0, p)
    a_star = 10.0 ** rng.uniform(-3, 1, (p, n_per))
    ref = DenseCalibrationDensity(*prob.args()).pieces_nuggets(prob.theta_star, a, a_star)
    fast = KronCalibrationDensity(*prob.args()).pieces_nuggets(prob.theta_star, a, a_star)
    _assert_agree(fast, ref)


@settings(max_examples=60, deadline=None)
@given(problems())
def test_training_matches_dense(prob: Problem) -> None:
    args = (prob.theta, prob.x, prob.kernels, prob.ktk, prob.w, prob.lam)
    _assert_agree(kron_training_logpdf(*args), dense_training_logpdf(*args))
    _assert_agree(training_logpdf(*args, kind="dense"), training_logpdf(*args))


@pytest.mark.parametrize("lam_star", [1e-2, 1.0, 1e3])
def test_theta_star_on_a_design_point(lam_star: float) -> None:
    """theta* = theta_k makes the Schur complement a small difference of large terms."""
    rng = np.random.default_rng(11)
    n_runs, n_per, t, s = 6, 5, 2, 2
    theta, x = rng.random((n_runs, t)), rng.random((n_per, s))
    kernels = [SeparableKernel(rng.uniform(0.3, 0.99, t + s), 0.5, t) for _ in range(2)]
    args = (theta, x, kernels, np.array([3.0, 1.5]), rng.normal(size=(n_runs * n_per, 2)))
    w_star = rng.normal(size=(n_per, 2))
    ref = DenseCalibrationDensity(*args, w_star).pieces(theta[2], 200.0, lam_star)
    fast = KronCalibrationDensity(*args, w_star).pieces(theta[2], 200.0, lam_star)
    _assert_agree(fast, ref)


def test_dense_matches_scipy_multivariate_normal() -> None:
    """The reference itself, against an independent Gaussian log-density."""
    rng = np.random.default_rng(4)
    theta, x = rng.random((4, 2)), rng.random((3, 1))
    kern = SeparableKernel(np.array([0.3, 0.6, 0.2]), 1.7, 2)
    obs = np.array([0, 2])
    ts = rng.random(2)
    cov = calibration_covariance(theta, x, kern, 0.05, theta_star=ts, obs_index=obs, a_star=0.4)
    v = rng.normal(size=cov.shape[0])
    got = dense_logpdf(v, theta, x, kern, 0.05, theta_star=ts, obs_index=obs, a_star=0.4)
    # Two Cholesky-based implementations of the same formula: rounding only.
    assert got.logpdf == pytest.approx(stats.multivariate_normal(cov=cov).logpdf(v), rel=1e-12)
    sign, logdet = np.linalg.slogdet(cov)
    assert sign == 1.0
    assert got.logdet == pytest.approx(logdet, rel=1e-12, abs=1e-12)
    assert got.quad == pytest.approx(v @ np.linalg.solve(cov, v), rel=1e-12)


def test_make_algebra_gives_interchangeable_back_ends() -> None:
    rng = np.random.default_rng(5)
    theta, x = rng.random((5, 3)), rng.random((4, 2))
    kernels = [SeparableKernel(rng.uniform(0.1, 0.9, 5), 1.0, 3)]
    args = (theta, x, kernels, np.array([2.0]), rng.normal(size=(20, 1)), rng.normal(size=(4, 1)))
    ts = rng.random(3)
    fast, dense = make_algebra("kronecker", *args), make_algebra("dense", *args)
    assert isinstance(fast, KronCalibrationDensity)
    assert isinstance(dense, DenseCalibrationDensity)
    _assert_agree(fast.pieces(ts, 30.0, 2.0), dense.pieces(ts, 30.0, 2.0))
    assert fast.logpdf(ts, 30.0, 2.0) == fast.pieces(ts, 30.0, 2.0).logpdf
    with pytest.raises(ValueError, match="'kronecker' or 'dense'"):
        make_algebra("cholesky", *args)  # type: ignore[arg-type]


def test_with_observations_equals_a_fresh_build() -> None:
    rng = np.random.default_rng(6)
    theta, x = rng.random((5, 2)), rng.random((4, 2))
    kernels = [SeparableKernel(rng.uniform(0.1, 0.9, 4), 1.0, 2) for _ in range(2)]
    base = (theta, x, kernels, np.array([2.0, 1.0]), rng.normal(size=(20, 2)))
    old, new = rng.normal(size=(4, 2)), rng.normal(size=(4, 2))
    ts = rng.random(2)
    original = KronCalibrationDensity(*base, old)
    before = original.pieces(ts, 10.0, 3.0)
    updated = original.with_observations(new)
    fresh = KronCalibrationDensity(*base, new)
    assert updated.pieces(ts, 10.0, 3.0) == fresh.pieces(ts, 10.0, 3.0)
    assert updated.pieces(ts, 10.0, 3.0) != before
    # The original object is unchanged (immutability).
    assert original.pieces(ts, 10.0, 3.0) == before


def test_changing_lambda_between_calls_gives_fresh_results() -> None:
    """The simulator-block memo (keyed on a) must never serve a stale lambda."""
    rng = np.random.default_rng(8)
    theta, x = rng.random((5, 2)), rng.random((4, 2))
    kernels = [SeparableKernel(rng.uniform(0.1, 0.9, 4), 1.0, 2) for _ in range(2)]
    args = (
        theta,
        x,
        kernels,
        np.array([2.0, 1.0]),
        rng.normal(size=(20, 2)),
        rng.normal(size=(4, 2)),
    )
    ts = rng.random(2)
    reused = KronCalibrationDensity(*args)
    for lam in (10.0, 300.0, 10.0, 300.0):
        assert reused.pieces(ts, lam, 3.0) == KronCalibrationDensity(*args).pieces(ts, lam, 3.0)


def test_shape_and_method_errors() -> None:
    rng = np.random.default_rng(7)
    theta, x = rng.random((3, 1)), rng.random((4, 1))
    kernels = [SeparableKernel(np.array([0.5, 0.5]), 1.0, 1)]
    w = rng.normal(size=(12, 1))
    with pytest.raises(ValueError, match=r"expected w of shape \(3 runs x 4 periods, 1 bases\)"):
        KronCalibrationDensity(theta, x, kernels, [1.0], w[:11], rng.normal(size=(4, 1)))
    with pytest.raises(ValueError, match=r"expected w_star of shape \(2, 1\)"):
        KronCalibrationDensity(theta, x, kernels, [1.0], w, rng.normal(size=(4, 1)), [0, 1])
    with pytest.raises(ValueError, match="needs every period observed"):
        KronCalibrationDensity(
            theta, x, kernels, [1.0], w, rng.normal(size=(2, 1)), [0, 1], method="eigen"
        )
    fast = KronCalibrationDensity(theta, x, kernels, [1.0], w, rng.normal(size=(4, 1)))
    with pytest.raises(ValueError, match="must be > 0"):
        fast.pieces_nuggets([0.5], [0.1], [0.0])
    with pytest.raises(ValueError, match="distinct period indices"):
        KronCalibrationDensity(theta, x, kernels, [1.0], w, rng.normal(size=(2, 1)), [1, 1])
