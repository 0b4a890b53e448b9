"""Sobol screening through a quick GP: the GP itself, and indices known exactly."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize
from scipy.stats import qmc

from bayescal.errors import ConfigError
from bayescal.screening import fit_scalar_gp, propose, sobol_indices
from bayescal.screening.surrogate import matern52

pytest.importorskip("SALib", reason="screening needs SALib")


def _lhs(n: int, k: int, seed: int) -> np.ndarray:
    return qmc.LatinHypercube(d=k, rng=np.random.default_rng(seed)).random(n)


def _ishigami(u: np.ndarray) -> np.ndarray:
    t = -np.pi + 2.0 * np.pi * u
    return np.sin(t[:, 0]) + 7.0 * np.sin(t[:, 1]) ** 2 + 0.1 * t[:, 2] ** 4 * np.sin(t[:, 0])


# Ishigami (a = 7, b = 0.1) with a fourth, inert input: S1 and ST are known exactly
_V = 0.5 + 7.0**2 / 8 + 0.1 * np.pi**4 / 5 + 0.1**2 * np.pi**8 / 18
_V1 = 0.5 * (1 + 0.1 * np.pi**4 / 5) ** 2
_V13 = 0.1**2 * np.pi**8 * (1 / 18 - 1 / 50)
ISHIGAMI_S1 = np.array([_V1, 7.0**2 / 8, 0.0, 0.0]) / _V
ISHIGAMI_ST = np.array([_V1 + _V13, 7.0**2 / 8, _V13, 0.0]) / _V


def test_the_likelihood_gradient_is_exact() -> None:
    from bayescal.screening.surrogate import _objective

    rng = np.random.default_rng(0)
    x = rng.random((30, 3))
    z = np.sin(3 * x[:, 0]) + x[:, 1] ** 2
    z = (z - z.mean()) / z.std()
    theta = np.r_[np.log([0.3, 0.7, 2.0]), 0.2, np.log(1e-3)]
    error = optimize.check_grad(
        lambda t: _objective(t, x, z)[0], lambda t: _objective(t, x, z)[1], theta
    )
    assert error < 1e-4 * np.linalg.norm(_objective(theta, x, z)[1])


def test_gp_leave_one_out_and_paths() -> None:
    x = _lhs(40, 2, 1)
    y = np.sin(5 * x[:, 0]) + 0.3 * x[:, 1]
    gp = fit_scalar_gp(x, y, seed=1)
    # the closed-form leave-one-out equals refitting the kriging predictor without the run
    mean, var = gp.loo()
    i = 7
    keep = np.arange(40) != i
    z = (y - gp.centre) / gp.scale
    cov = matern52(x[keep], x[keep], gp.lengths, gp.variance) + (gp.nugget + 1e-10) * np.eye(39)
    cross = matern52(x[i : i + 1], x[keep], gp.lengths, gp.variance)
    beta = gp.beta  # the closed form keeps beta
    direct = beta + cross @ np.linalg.solve(cov, z[keep] - beta)
    assert mean[i] == pytest.approx(gp.centre + gp.scale * direct[0], rel=1e-6)
    assert var[i] > 0
    assert gp.q2 > 0.99  # a smooth function of two inputs from 40 runs
    # joint posterior paths: their spread is the kriging variance, their mean the prediction
    # (from 6 runs, where the GP is unsure between them)
    few = fit_scalar_gp(x[:6], y[:6], seed=1)
    points = np.random.default_rng(2).random((300, 2))
    m, v = few.predict(points)
    assert np.mean(v) > 0.01 * few.scale**2
    paths = few.sample_paths(points, 400, np.random.default_rng(3))
    assert paths.shape == (400, 300)
    assert np.mean(paths.var(axis=0)) == pytest.approx(np.mean(v), rel=0.2)
    assert np.mean(np.abs(paths.mean(axis=0) - m)) < 3 * np.sqrt(np.mean(v) / 400)


def test_a_linear_model_shares_the_variance_by_the_squared_slopes() -> None:
    a = np.array([4.0, 2.0, 1.0, 0.0, 0.5])
    truth = a**2 / np.sum(a**2)  # S1 = ST = a_i^2 / sum a^2 for independent U(0, 1) inputs
    x = _lhs(60, 5, 0)
    ix = sobol_indices(x, x @ a, list("abcde"), "y", seed=4)
    assert ix.q2 > 0.999
    assert ix.reliable
    tol = 1e-6  # the inert input's indices are 0 to rounding
    assert np.all(ix.st_lower <= truth + tol)
    assert np.all(truth <= ix.st_upper + tol)
    assert np.all(ix.s1_lower <= truth + tol)
    assert np.all(truth <= ix.s1_upper + tol)
    # the intervals are the Saltelli sample's error here (the GP is exact): a few hundredths
    assert np.max(ix.st_upper - ix.st_lower) < 0.15
    np.testing.assert_allclose(ix.st, truth, atol=0.03)
    assert list(ix.ranks) == [1, 2, 3, 5, 4]


def test_ishigami_indices_from_100_runs() -> None:
    x = _lhs(100, 4, 1)
    ix = sobol_indices(x, _ishigami(x), ["x1", "x2", "x3", "inert"], "y", seed=1)
    assert 0.8 < ix.q2 < 1.0
    # each true index lies within its 95 % interval (the GP paths' and the Saltelli sample's;
    # at this seed: the interval holds the GP at fixed hyperparameters, and other hypercubes
    # of 100 runs can miss x2's ST by a few hundredths)
    tol = 1e-6  # the inert input's indices are 0 to rounding
    assert np.all(ix.st_lower <= ISHIGAMI_ST + tol)
    assert np.all(ix.st_upper + tol >= ISHIGAMI_ST)
    assert np.all(ix.s1_lower <= ISHIGAMI_S1 + tol)
    assert np.all(ix.s1_upper + tol >= ISHIGAMI_S1)
    # x3 acts only through its interaction with x1: small S1, clear ST; the inert input is 0
    assert ix.s1[2] < 0.05 < 0.1 < ix.st[2]
    assert ix.st_upper[3] < 0.02
    assert set(np.argsort(-ix.st)[:2]) == {0, 1}
    proposal = propose([ix], threshold=0.1)
    assert proposal.measure == "ST"
    assert set(proposal.selected) == {"x1", "x2", "x3"}


def test_a_rough_fit_is_flagged_and_a_flat_output_is_zero() -> None:
    x = _lhs(12, 3, 5)
    rough = np.sin(40 * x[:, 0]) * np.cos(30 * x[:, 1])  # far too wiggly for 12 runs
    ix = sobol_indices(x, rough, ["a", "b", "c"], "y", paths=5, seed=2)
    assert ix.q2 < 0.8
    assert not ix.reliable
    flat = sobol_indices(x, np.full(12, 3.0), ["a", "b", "c"], "y")
    assert flat.reliable
    assert np.all(flat.st == 0)
    assert np.all(flat.normalised == 0)


def test_failed_runs_are_left_out() -> None:
    x = _lhs(20, 3, 6)
    y = x @ np.array([1.0, 0.2, 0.0])
    y[[2, 5]] = np.nan
    ix = sobol_indices(x, y, ["a", "b", "c"], "y", paths=5)
    assert ix.runs == 18
    y[:16] = np.nan
    with pytest.raises(ConfigError, match="only 4 of 20 screening runs succeeded"):
        sobol_indices(x, y, ["a", "b", "c"], "y")
