"""Vectorised (lockstep) chains and the batched calibration likelihood (issue 7).

* ``KronCalibrationDensity.logpdf_batch`` against a loop of ``logpdf``, and the
  batched posterior against ``CalibrationPosterior`` row by row (``-inf``
  outside the prior);
* lockstep Metropolis-within-Gibbs against the serial sampler: bit-identical
  draws when the batched target equals the scalar one row by row, identical
  draws and log-densities equal to rounding for the calibration posterior;
* lockstep draws of a Gaussian target (with truncated coordinates, so that the
  logit and log maps are used) against its exact means, within 4 Monte Carlo
  standard errors (MCSE from ArviZ's ESS of each chain set; a false alarm of
  6e-5 per comparison for Gaussian errors; the seeds are fixed anyway).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import stats

from bayescal.calibration.kron import KronCalibrationDensity
from bayescal.calibration.target import BatchedPosterior, CalibrationPosterior
from bayescal.design import BetaPrior, UniformPrior
from bayescal.errors import ConfigError
from bayescal.mcmc import MetropolisWithinGibbs, run_chains
from bayescal.mcmc.diagnostics import import_arviz
from bayescal.mcmc.samplers import AdaptiveMetropolis
from bayescal.mcmc.samplers.lockstep import as_lockstep, run_lockstep
from random_density import random_density

N_SE = 4.0  # tolerance in Monte Carlo standard errors (see module docstring)
# Batch and loop make the same BLAS calls per point; only the order of the final
# sums over p (R m* + m*) terms differs, a relative error of a few 1e-16 of the
# sum of |terms|. 1e-12 of that sum leaves a margin of three orders.
REL = 1e-12


def _density(seed: int = 0, runs: int = 12, periods: int = 8) -> KronCalibrationDensity:
    """A calibration density on random data: t = 3, s = 2, p = 2 bases."""
    return random_density(seed, runs, periods)


def _scale(
    density: KronCalibrationDensity, ts: NDArray[np.float64], lam: float, ls: float
) -> float:
    """Sum of the magnitudes of the log-density's pieces: the size of its rounding."""
    pieces = density.pieces(ts, lam, ls)
    return abs(pieces.logdet) + abs(pieces.quad) + pieces.size * math.log(2 * math.pi)


def test_logpdf_batch_equals_a_loop_of_logpdf() -> None:
    density, reference = _density(), _density()
    rng = np.random.default_rng(1)
    n = 40
    ts = rng.random((n, 3))
    ts[:3] = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.5, 1e-12, 1.0 - 1e-12]]  # edges of the box
    lam = np.exp(rng.uniform(-3.0, 6.0, n))
    lam_star = np.exp(rng.uniform(-3.0, 6.0, n))
    got = density.logpdf_batch(ts, lam, lam_star)
    for k in range(n):
        want = reference.logpdf(ts[k], lam[k], lam_star[k])
        assert abs(got[k] - want) <= REL * _scale(reference, ts[k], lam[k], lam_star[k])
    # a second call (sessions keep nothing between logpdf_batch calls) and B = 1
    again = density.logpdf_batch(ts[::-1], lam[::-1], lam_star[::-1])
    np.testing.assert_array_equal(again, got[::-1])
    single = density.logpdf_batch(ts[:1], lam[:1], lam_star[:1])
    assert single[0] == pytest.approx(got[0], rel=REL)


def test_logpdf_batch_rejects_bad_shapes_and_precisions() -> None:
    density = _density()
    with pytest.raises(ValueError, match=r"theta_star \(B, 3\)"):
        density.logpdf_batch(np.zeros((2, 2)), [1.0, 1.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="must be > 0"):
        density.logpdf_batch(np.zeros((2, 3)), [1.0, 0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="errors must be"):
        density.logpdf_batch(np.zeros((1, 3)), [1.0], [1.0], errors="ignore")  # type: ignore[arg-type]


def test_not_positive_definite_rows_give_minus_inf_or_raise() -> None:
    density = _density()
    ts, lam, ls = np.full((3, 3), 0.5), np.array([1.0, 0.01, 0.001]), np.ones(3)
    session = density.batch_session(ts, lam, ls)
    assert session is not None
    assert session.ok.all()
    # An indefinite simulator block: one eigenvalue of S_theta of basis 0 set to -1, so
    # den = -l_x + a_0 with a_0 = 1 / (lam ktk_0) = 0.5 / lam is negative somewhere
    # exactly when a_0 <= max(l_x): for lam = 1 (a_0 = 0.5 < max l_x, as the S_x of 8
    # periods has eigenvalues summing to 8), not for lam = 0.01 or 0.001 (a_0 >= 50).
    l_t = session.grid.l_t.copy()
    l_t[0, 0] = -1.0
    bad = dataclasses.replace(session.grid, l_t=l_t)
    density._grid = bad
    expect_bad = (-bad.l_x[0].max() + 0.5 / lam) <= 0.0
    assert expect_bad.tolist() == [True, False, False]
    values = density.logpdf_batch(ts, lam, ls, errors="-inf")
    np.testing.assert_array_equal(np.isneginf(values), expect_bad)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        density.logpdf_batch(ts, lam, ls)


def _posterior(density: KronCalibrationDensity) -> CalibrationPosterior:
    priors = [UniformPrior(0.0, 1.0), BetaPrior(0.0, 2.0, a=2.0, b=3.0), UniformPrior(-1.0, 1.0)]
    return CalibrationPosterior(density, priors, (5.0, 5.0), (3.0, 1.5))


def test_batched_posterior_equals_the_scalar_one_and_is_minus_inf_outside() -> None:
    target = _posterior(_density())
    batched = _posterior(_density()).lockstep()
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(-0.1, 1.1, (30, 3)), rng.uniform(-0.2, 3.0, (30, 2))])
    got = batched(points)
    for k, row in enumerate(points):
        want = target(row)
        if want == -math.inf:
            assert got[k] == -math.inf
        else:
            assert abs(got[k] - want) <= REL * _scale(target.algebra, row[:3], row[3], row[4])
    assert np.isneginf(got).sum() >= 5  # points outside the prior were among them
    assert np.isfinite(got).sum() >= 5


# --- samplers ---------------------------------------------------------------------------

MEAN = np.array([1.0, -2.0])
SD = np.array([1.0, 0.5])
RHO = 0.8
TRUNC = ((0.3, 0.2, 0.0, 1.0), (0.5, 1.0, 0.0, math.inf))  # (mean, sd, lower, upper)


def gaussian_batch(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Correlated pair x0, x1 and two truncated normals x2 in (0, 1), x3 in (0, inf).

    Only + - * / so that a row of a batch is bit-identical to a single evaluation.
    """
    a = (points[:, 0] - MEAN[0]) / SD[0]
    b = (points[:, 1] - MEAN[1]) / SD[1]
    out = -0.5 * (a * a - 2.0 * RHO * a * b + b * b) / (1.0 - RHO * RHO)
    for col, (m, s, _, _) in zip((2, 3), TRUNC, strict=True):
        c = (points[:, col] - m) / s
        out = out - 0.5 * c * c
    inside = (points[:, 2] > 0.0) & (points[:, 2] < 1.0) & (points[:, 3] > 0.0)
    return np.where(inside, out, -math.inf)


class GaussianTarget:
    """The scalar form of :func:`gaussian_batch`, with its batched form as ``batch``."""

    def __call__(self, x: NDArray[np.float64]) -> float:
        return float(gaussian_batch(x[None, :])[0])

    def batch(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        return gaussian_batch(points)


def _gauss_sampler(n_burn: int) -> MetropolisWithinGibbs:
    return MetropolisWithinGibbs(
        n_burn=n_burn,
        lower=[-math.inf, -math.inf, 0.0, 0.0],
        upper=[math.inf, math.inf, 1.0, math.inf],
    )


STARTS = np.array([[0.0, -1.0, 0.5, 1.0], [2.0, -3.0, 0.2, 0.3], [1.0, -2.0, 0.8, 2.0],
                   [-1.0, -2.5, 0.4, 0.1], [0.5, -1.5, 0.6, 0.7]])  # fmt: skip


def test_lockstep_is_bit_identical_to_serial_chains() -> None:
    sampler = _gauss_sampler(300)
    kwargs: dict[str, Any] = {"seed": 11, "names": ("a", "b", "c", "d")}
    serial = run_chains(sampler, GaussianTarget(), STARTS, 400, backend="serial", **kwargs)
    calls: list[int] = []
    lockstep = run_chains(
        sampler, GaussianTarget(), STARTS, 400, backend="vectorised", callback=calls.append,
        **kwargs,
    )  # fmt: skip
    np.testing.assert_array_equal(lockstep.draws, serial.draws)
    np.testing.assert_array_equal(lockstep.log_density, serial.log_density)
    np.testing.assert_array_equal(lockstep.acceptance, serial.acceptance)
    for got, want in zip(lockstep.results, serial.results, strict=True):
        np.testing.assert_array_equal(got.scales, want.scales)
        assert got.rng_state == want.rng_state
    assert lockstep.names == ("a", "b", "c", "d")
    assert calls[-1] == 5 * (300 + 400)  # iterations over all chains
    assert np.ptp(lockstep.draws[:, :, 0]) > 0.0  # the chains moved


def test_lockstep_with_a_row_loop_and_start_functions_matches_serial() -> None:
    def target(x: NDArray[np.float64]) -> float:  # no batch method: looped over rows
        return float(gaussian_batch(x[None, :])[0])

    def start(rng: np.random.Generator) -> NDArray[np.float64]:
        return np.array([0.0, -2.0, 0.5, 1.0]) + 0.1 * rng.random(4)

    sampler = dataclasses.replace(_gauss_sampler(100), fixed=[1], bounds="reflect")
    serial = run_chains(sampler, target, start, 150, seed=5, n_chains=4, backend="serial")
    lockstep = run_chains(sampler, target, start, 150, seed=5, n_chains=4, backend="vectorised")
    np.testing.assert_array_equal(lockstep.draws, serial.draws)
    assert np.all(lockstep.draws[:, :, 1] == lockstep.draws[:, :1, 1])  # the fixed coordinate
    assert np.isnan(lockstep.acceptance[:, 1]).all()


def test_lockstep_draws_have_the_exact_means() -> None:
    az = import_arviz()
    chains = run_chains(
        _gauss_sampler(1000), GaussianTarget(), STARTS[:4], 4000, seed=3, backend="vectorised"
    )
    draws = chains.draws  # (4, 4000, 4)
    exact = list(MEAN)
    for m, s, lo, hi in TRUNC:
        exact.append(float(stats.truncnorm((lo - m) / s, (hi - m) / s, loc=m, scale=s).mean()))
    for k, want in enumerate(exact):
        mcse = float(az.mcse(draws[:, :, k], method="mean"))
        assert abs(draws[:, :, k].mean() - want) < N_SE * mcse, (k, want)
    assert np.all(chains.acceptance > 0.2)  # the adaptation kept the chains moving


def test_calibration_posterior_lockstep_equals_serial() -> None:
    sampler = MetropolisWithinGibbs(
        n_burn=150,
        lower=[0.0, 0.0, 0.0, 0.0, 0.0],
        upper=[1.0, 1.0, 1.0, math.inf, math.inf],
        scales=[0.5, 0.5, 0.5, 1.0, 1.0],
        batch_size=25,
        max_adapt=0.25,
    )
    starts = np.column_stack([np.random.default_rng(4).uniform(0.1, 0.9, (4, 3)), np.ones((4, 2))])
    serial = run_chains(sampler, _posterior(_density()), starts, 200, seed=8, backend="serial")
    lockstep = run_chains(
        sampler, _posterior(_density()), starts, 200, seed=8, backend="vectorised"
    )
    # Identical draws: the log-densities differ by rounding only (~1e-15 relative), which
    # changes an acceptance only if a test falls that close to its threshold (chance
    # ~1e-12 over this run).
    np.testing.assert_array_equal(lockstep.draws, serial.draws)
    np.testing.assert_allclose(lockstep.log_density, serial.log_density, rtol=REL)
    np.testing.assert_array_equal(lockstep.acceptance, serial.acceptance)
    assert isinstance(as_lockstep(_posterior(_density())), BatchedPosterior)


def test_run_lockstep_rejects_bad_starts() -> None:
    rngs = [np.random.default_rng(k) for k in range(2)]
    bad = STARTS[:2].copy()
    bad[1, 2] = 2.0  # outside (0, 1)
    with pytest.raises(ConfigError, match="not strictly inside"):
        run_lockstep(_gauss_sampler(10), gaussian_batch, bad, 5, rngs)
    with pytest.raises(ConfigError, match="n_chains = 2"):
        run_lockstep(_gauss_sampler(10), gaussian_batch, STARTS[:3], 5, rngs)


def test_vectorised_backend_is_refused_where_it_does_not_apply(tmp_path: Any) -> None:
    with pytest.raises(ConfigError, match="needs a MetropolisWithinGibbs"):
        run_chains(AdaptiveMetropolis(n_burn=10), GaussianTarget(), STARTS, 5, seed=0,
                   backend="vectorised")  # fmt: skip
    with pytest.raises(ConfigError, match="chain backend must be one of"):
        run_chains(_gauss_sampler(10), GaussianTarget(), STARTS, 5, seed=0,
                   backend="gpu")  # type: ignore[arg-type]  # fmt: skip
