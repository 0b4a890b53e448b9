"""Statistical and functional tests of the MCMC samplers and of running several chains.

Statistical tests sample seeded targets with known moments and accept an estimate
when it lies within 4 Monte Carlo standard errors (MCSE) of the exact value. The
MCSE of each estimated expectation E[f(x)] comes from the chains' own effective
sample size (ArviZ's ``mcse(method="mean")`` applied to the values f(draws)), so the
tolerance follows the sampler's actual efficiency. Moments are centred on the exact
mean, so each is a plain expectation: variance E[(x - m)^2], correlation
E[(x_i - m_i)(x_j - m_j)] / (s_i s_j). With Gaussian errors, 4 MCSE leaves a false
alarm of 6e-5 per comparison; the seeds are fixed anyway.
"""

from __future__ import annotations

import math
import pickle
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import linalg, stats

from bayescal.errors import ConfigError
from bayescal.mcmc import (
    AdaptiveMetropolis,
    Chains,
    LogDensityError,
    MetropolisWithinGibbs,
    Sampler,
    dispersed_starts,
    run_chains,
)
from bayescal.mcmc.samplers.base import BoundsMethod, Box

N_SE = 4.0  # tolerance in Monte Carlo standard errors (see module docstring)


def import_arviz() -> Any:
    """ArviZ without its once-a-day FutureWarning about its own 1.0 migration."""
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message=r"\s*ArviZ is undergoing a major refactor", category=FutureWarning
        )
        import arviz

    return arviz


# --- targets (module-level classes so that worker processes can unpickle them) ----------


class Gaussian:
    """Multivariate normal log-density (up to a constant), via a Cholesky factor."""

    def __init__(self, mean: NDArray[np.float64], cov: NDArray[np.float64]) -> None:
        self.mean = np.asarray(mean, dtype=float)
        self.chol = linalg.cho_factor(cov, lower=True)

    def __call__(self, x: NDArray[np.float64]) -> float:
        r = x - self.mean
        return -0.5 * float(r @ linalg.cho_solve(self.chol, r))


class Beta:
    """Beta(a, b) log-density on (0, 1), -inf outside."""

    def __init__(self, a: float, b: float) -> None:
        self.a, self.b = a, b

    def __call__(self, x: NDArray[np.float64]) -> float:
        v = float(x[0])
        if not 0.0 < v < 1.0:
            return -math.inf
        return (self.a - 1.0) * math.log(v) + (self.b - 1.0) * math.log1p(-v)


class RhoAsBeta:
    """Beta(a, b) prior of rho sampled as beta = -4 ln(rho) on [0, inf) (GPMSA).

    log p(beta) = log p_rho(rho) + log |d rho / d beta| with rho = exp(-beta/4),
    1 - rho = -expm1(-beta/4) computed without cancellation near rho = 1.
    """

    def __init__(self, a: float, b: float) -> None:
        self.a, self.b = a, b

    def __call__(self, x: NDArray[np.float64]) -> float:
        beta = float(x[0])
        if not beta > 0.0:
            return -math.inf
        log_rho = -beta / 4.0
        log_1m_rho = math.log(-math.expm1(log_rho))
        return (self.a - 1.0) * log_rho + (self.b - 1.0) * log_1m_rho + log_rho - math.log(4.0)


class LinearGaussian:
    """Calibration y = A theta + noise, noise ~ N(0, sigma^2 I), prior theta ~ N(m0, s0^2 I)."""

    def __init__(self, a: NDArray[np.float64], y: NDArray[np.float64], sigma: float,
                 m0: NDArray[np.float64], s0: float) -> None:  # fmt: skip
        self.a, self.y, self.sigma, self.m0, self.s0 = a, y, sigma, m0, s0

    def __call__(self, theta: NDArray[np.float64]) -> float:
        r = self.y - self.a @ theta
        p = theta - self.m0
        return -0.5 * float(r @ r) / self.sigma**2 - 0.5 * float(p @ p) / self.s0**2

    def posterior(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Exact posterior mean and covariance from the normal equations."""
        d = self.a.shape[1]
        precision = self.a.T @ self.a / self.sigma**2 + np.eye(d) / self.s0**2
        factor = linalg.cho_factor(precision, lower=True)
        rhs = self.a.T @ self.y / self.sigma**2 + self.m0 / self.s0**2
        return linalg.cho_solve(factor, rhs), linalg.cho_solve(factor, np.eye(d))


def zero_log_density(x: NDArray[np.float64]) -> float:
    """A flat target, for reproducibility and bookkeeping tests."""
    return 0.0


def nan_log_density(x: NDArray[np.float64]) -> float:
    """NaN away from the start: a model bug the sampler must report."""
    return 0.0 if x[0] == 0.0 else math.nan


# --- helpers ------------------------------------------------------------------------------


def moment_errors(
    draws: NDArray[np.float64], mean: NDArray[np.float64], cov: NDArray[np.float64]
) -> dict[str, float]:
    """(estimate - exact) / MCSE for means, variances and correlations of draws (c, n, d)."""
    az = import_arviz()
    sd = np.sqrt(np.diag(cov))
    out: dict[str, float] = {}

    def z(name: str, values: NDArray[np.float64], exact: float) -> None:
        out[name] = float((values.mean() - exact) / az.mcse(values, method="mean"))

    d = draws.shape[2]
    for i in range(d):
        z(f"mean[{i}]", draws[..., i], mean[i])
        z(f"var[{i}]", (draws[..., i] - mean[i]) ** 2, cov[i, i])
        for j in range(i + 1, d):
            prod = (draws[..., i] - mean[i]) * (draws[..., j] - mean[j]) / (sd[i] * sd[j])
            z(f"corr[{i},{j}]", prod, cov[i, j] / (sd[i] * sd[j]))
    return out


def assert_within_mcse(errors: dict[str, float]) -> None:
    worst = max(errors, key=lambda k: abs(errors[k]))
    assert abs(errors[worst]) < N_SE, f"{worst} off by {errors[worst]:.2f} MCSE: {errors}"


def ks_pvalue(draws: NDArray[np.float64], cdf: Any) -> float:
    """KS p-value of pooled draws (c, n) against ``cdf`` with n = the draws' ESS.

    Autocorrelated draws fluctuate like ESS independent ones, so the Kolmogorov
    distribution is evaluated at the smaller of the bulk and tail ESS.
    """
    az = import_arviz()
    n_eff = min(az.ess(draws, method="bulk"), az.ess(draws, method="tail"))
    statistic = stats.kstest(draws.ravel(), cdf).statistic
    return float(stats.kstwo.sf(statistic, int(n_eff)))


SAMPLERS: dict[str, Callable[..., Sampler]] = {
    "mwg": MetropolisWithinGibbs,
    "rwm": AdaptiveMetropolis,
}

CORR_COV = np.array([[1.0, 0.8, 0.3], [0.8, 2.0, -0.5], [0.3, -0.5, 1.5]])
CORR_MEAN = np.array([1.0, -2.0, 0.5])


# --- known targets --------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["mwg", "rwm"])
def test_correlated_gaussian_moments(kind: str) -> None:
    target = Gaussian(CORR_MEAN, CORR_COV)
    sampler = SAMPLERS[kind](n_burn=3000)
    starts = dispersed_starts([-np.inf] * 3, [np.inf] * 3, 4, np.random.default_rng(0), spread=3.0)
    chains = run_chains(sampler, target, starts, 6000, seed=11, backend="serial")
    assert_within_mcse(moment_errors(chains.draws, CORR_MEAN, CORR_COV))


@pytest.mark.parametrize("bounds", ["transform", "reflect"])
def test_beta_2_5_with_bounds(bounds: BoundsMethod) -> None:
    a, b = 2.0, 5.0
    sampler = MetropolisWithinGibbs(n_burn=2000, lower=[0.0], upper=[1.0], bounds=bounds)
    chains = run_chains(sampler, Beta(a, b), lambda r: r.uniform(0.1, 0.9, 1), 6000,
                        seed=5, backend="serial")  # fmt: skip
    dist = stats.beta(a, b)
    errors = moment_errors(chains.draws, np.array([dist.mean()]), np.array([[dist.var()]]))
    assert_within_mcse(errors)
    # 0.01: a 1 % false alarm under the ESS-based Kolmogorov distribution.
    assert ks_pvalue(chains.draws[..., 0], dist.cdf) > 0.01


@pytest.mark.parametrize("kind", ["mwg", "rwm"])
def test_rho_prior_beta_1_01_piled_at_one(kind: str) -> None:
    """The emulator's rho prior Beta(1, 0.1), sampled as beta = -4 ln(rho) >= 0."""
    a, b = 1.0, 0.1
    sampler = SAMPLERS[kind](n_burn=4000, lower=[0.0])
    chains = run_chains(sampler, RhoAsBeta(a, b), lambda r: r.uniform(0.5, 4.0, 1), 10000,
                        seed=8, backend="serial")  # fmt: skip
    beta = chains.draws
    dist = stats.beta(a, b)
    errors = moment_errors(np.exp(-beta / 4.0), np.array([dist.mean()]), np.array([[dist.var()]]))
    assert_within_mcse(errors)

    def cdf_beta(values: NDArray[np.float64]) -> NDArray[np.float64]:
        # P(beta <= v) = P(1 - rho <= -expm1(-v/4)) with 1 - rho ~ Beta(b, a). The KS test
        # runs on beta, not rho: 2.5 % of the draws have 1 - rho < 1.1e-16 and would
        # all round to rho = 1.0, a float64 artefact of about 0.025 in the KS distance.
        return stats.beta(b, a).cdf(-np.expm1(-values / 4.0))

    # 0.01: a 1 % false alarm under the ESS-based Kolmogorov distribution.
    assert ks_pvalue(beta[..., 0], cdf_beta) > 0.01


def linear_gaussian_problem() -> LinearGaussian:
    rng = np.random.default_rng(2024)
    a = rng.normal(size=(30, 3)) @ np.array([[1.0, 0.7, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])
    theta_true = np.array([0.3, 0.6, 0.45])
    sigma = 0.5
    y = a @ theta_true + sigma * rng.normal(size=30)
    return LinearGaussian(a, y, sigma, m0=np.full(3, 0.5), s0=1.0)


@pytest.mark.parametrize("kind", ["mwg", "rwm"])
def test_linear_gaussian_calibration_posterior(kind: str) -> None:
    problem = linear_gaussian_problem()
    mean, cov = problem.posterior()
    sampler = SAMPLERS[kind](n_burn=3000, scales=0.2)
    starts = mean + 0.5 * np.random.default_rng(1).normal(size=(4, 3))
    chains = run_chains(sampler, problem, starts, 6000, seed=21, backend="serial")
    assert_within_mcse(moment_errors(chains.draws, mean, cov))


# --- behaviour ---------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["mwg", "rwm"])
def test_same_seed_same_draws_different_seed_different(kind: str) -> None:
    sampler = SAMPLERS[kind](n_burn=100, lower=[0.0, -np.inf], upper=[1.0, np.inf])
    target = Gaussian(np.array([0.5, 0.0]), np.eye(2))
    starts = np.array([[0.5, 0.0]] * 4)
    serial = run_chains(sampler, target, starts, 300, seed=7, backend="serial")
    again = run_chains(sampler, target, starts, 300, seed=7, backend="serial")
    in_processes = run_chains(sampler, target, starts, 300, seed=7, backend="processes")
    other = run_chains(sampler, target, starts, 300, seed=8, backend="serial")
    assert np.array_equal(serial.draws, again.draws)
    assert np.array_equal(serial.draws, in_processes.draws)
    assert not np.array_equal(serial.draws[0], serial.draws[1])  # chains get distinct streams
    assert not np.any(np.all(serial.draws == other.draws, axis=(1, 2)))


def test_recorded_generator_state_reproduces_a_chain() -> None:
    sampler = MetropolisWithinGibbs(n_burn=50)
    target = Gaussian(np.zeros(2), np.eye(2))
    first = sampler.run(target, [0.0, 0.0], 200, np.random.default_rng(99))
    rng = np.random.default_rng()
    rng.bit_generator.state = first.rng_state
    second = sampler.run(target, [0.0, 0.0], 200, rng)
    assert np.array_equal(first.draws, second.draws)


@pytest.mark.parametrize("kind", ["mwg", "rwm"])
def test_fixed_coordinates_do_not_move(kind: str) -> None:
    sampler = SAMPLERS[kind](n_burn=200, fixed=[1], lower=[-np.inf, 0.0, -np.inf],
                             upper=[np.inf, 1.0, np.inf])  # fmt: skip
    result = sampler.run(Gaussian(np.zeros(3), np.eye(3)), [0.1, 0.3, -0.2], 500,
                         np.random.default_rng(3))  # fmt: skip
    assert np.all(result.draws[:, 1] == 0.3)
    assert np.isnan(result.acceptance[1])
    assert result.scales[1] == 0.0
    assert np.ptp(result.draws[:, 0]) > 0
    assert np.ptp(result.draws[:, 2]) > 0


def test_mwg_bookkeeping_and_no_adaptation_after_burn_in() -> None:
    calls: list[int] = []
    sampler = MetropolisWithinGibbs(n_burn=0, thin=3, scales=[0.5, 2.0])
    result = sampler.run(zero_log_density, [0.0, 0.0], 40, np.random.default_rng(0), calls.append)
    assert result.draws.shape == (40, 2)
    assert result.log_density.shape == (40,)
    assert calls == list(range(1, 121))  # one call per iteration, thin included
    # No burn-in, no adaptation: the proposal widths are still the initial ones.
    assert result.scales.tolist() == [0.5, 2.0]
    # A flat target accepts every proposal.
    assert result.acceptance.tolist() == [1.0, 1.0]


def test_mwg_adapts_towards_target_acceptance_during_burn_in() -> None:
    # A 1-D standard normal with a far too small initial width (0.01); with the fast
    # cap max_adapt = 0.1 the burn-in can move the log-width by up to ~0.1 per batch.
    sampler = MetropolisWithinGibbs(n_burn=20000, scales=0.01, max_adapt=0.1)
    result = sampler.run(Gaussian(np.zeros(1), np.eye(1)), [0.0], 20000, np.random.default_rng(4))
    # The acceptance of a fixed width s is a smooth function of s; the adaptation
    # hovers within ~0.1 in log-width of the 0.44 width (s ~ 2.4), a few % in rate.
    assert abs(result.acceptance[0] - 0.44) < 0.05
    assert 1.5 < result.scales[0] < 3.5


def test_parallel_callback_reports_total_progress() -> None:
    seen: list[int] = []
    sampler = MetropolisWithinGibbs(n_burn=100)
    run_chains(sampler, zero_log_density, np.zeros((4, 1)), 200, seed=1, callback=seen.append)
    assert seen
    assert seen[-1] == 4 * 300
    assert seen == sorted(seen)


def test_box_transform_round_trip_and_jacobian() -> None:
    box = Box.build(4, [0.0, -np.inf, 2.0, -np.inf], [1.0, 5.0, np.inf, np.inf], "transform")
    x = np.array([0.2, 3.0, 2.5, -7.0])
    z = box.to_sampling(x)
    back, log_jac = box.to_original(z)
    np.testing.assert_allclose(back, x, rtol=1e-14)  # round-off only
    # log |dx/dz| against central differences of each coordinate's map
    h = 1e-6
    numeric = sum(
        math.log(abs((box.to_original(z + h * e)[0] - box.to_original(z - h * e)[0])[i] / (2 * h)))
        for i, e in enumerate(np.eye(4))
    )
    assert log_jac == pytest.approx(numeric, abs=1e-8)  # O(h^2) difference error


def test_box_reflection_folds_into_the_interval() -> None:
    box = Box.build(3, [0.0, 1.0, -np.inf], [1.0, np.inf, 2.0], "reflect")
    x, log_jac = box.to_original(np.array([2.3, -0.5, 3.25]))
    np.testing.assert_allclose(x, [0.3, 2.5, 0.75], rtol=0, atol=1e-15)
    assert log_jac == 0.0


def test_dispersed_starts_cover_the_box() -> None:
    starts = dispersed_starts([0.0, 1.0, -np.inf], [10.0, np.inf, np.inf], 4,
                              np.random.default_rng(0), center=[0.0, 3.0, 0.0])  # fmt: skip
    assert starts.shape == (4, 3)
    # Latin hypercube over the middle 90 %: one start in each quarter of [0.5, 9.5].
    assert sorted(np.floor((starts[:, 0] - 0.5) / 2.25).tolist()) == [0, 1, 2, 3]
    assert np.all(starts[:, 1] > 1.0)


# --- errors a user can cause ------------------------------------------------------------------


def test_nan_log_density_is_an_error_not_a_rejection() -> None:
    with pytest.raises(LogDensityError, match="returned nan"):
        MetropolisWithinGibbs(n_burn=10).run(nan_log_density, [0.0], 10, np.random.default_rng(0))
    with pytest.raises(LogDensityError, match="returned nan"):
        AdaptiveMetropolis(n_burn=10).run(nan_log_density, [0.0], 10, np.random.default_rng(0))


@pytest.mark.parametrize("kind", ["mwg", "rwm"])
def test_bad_start_raises_config_error(kind: str) -> None:
    sampler = SAMPLERS[kind](lower=[0.0], upper=[1.0])
    with pytest.raises(ConfigError, match="not strictly inside its bounds"):
        sampler.run(Beta(2, 5), [1.0], 10, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="-inf at the starting point"):
        SAMPLERS[kind]().run(Beta(2, 5), [3.0], 10, np.random.default_rng(0))


def test_invalid_settings_raise_config_error() -> None:
    with pytest.raises(ConfigError, match="n_burn must be an integer >= 0"):
        MetropolisWithinGibbs(n_burn=-1)
    with pytest.raises(ConfigError, match="target acceptance"):
        AdaptiveMetropolis(target=1.5)
    with pytest.raises(ConfigError, match="lower < upper"):
        MetropolisWithinGibbs(lower=[1.0], upper=[0.0]).run(zero_log_density, [0.5], 5,
                                                             np.random.default_rng(0))  # fmt: skip
    with pytest.raises(ConfigError, match=r"starts must have shape \(n_chains, d\)"):
        run_chains(
            MetropolisWithinGibbs(), zero_log_density, np.zeros((3, 1)), 5, seed=0, n_chains=4
        )


def test_unpicklable_log_density_is_reported_before_starting_processes() -> None:
    with pytest.raises(ConfigError, match="backend='serial'"):
        run_chains(MetropolisWithinGibbs(n_burn=5), lambda x: 0.0, np.zeros((4, 1)), 5, seed=0)


def test_chains_pickle_and_shapes() -> None:
    chains = run_chains(MetropolisWithinGibbs(n_burn=10), zero_log_density, np.zeros((4, 2)), 25,
                        seed=3, names=["a", "b"], backend="serial")  # fmt: skip
    assert isinstance(pickle.loads(pickle.dumps(chains)), Chains)
    assert chains.draws.shape == (4, 25, 2)
    assert chains.log_density.shape == (4, 25)
    assert chains.acceptance.shape == (4, 2)
    assert chains.names == ("a", "b")
    assert chains.seed == 3
