"""Tests of the convergence diagnostics on chains with known behaviour.

Chains are built directly (independent normal draws, shifted chains, frozen chains)
so that the right verdict is known without running a sampler; one test runs the
samplers end to end. R-hat is checked against an independent implementation of the
formulas: the classical split R-hat (Gelman et al., BDA3, section 11.4) and its
rank-normalised version (Vehtari et al. 2021, eqs. 14 and folded variant).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import stats

from bayescal.errors import ConfigError
from bayescal.mcmc import (
    AdaptiveMetropolis,
    Diagnostics,
    MetropolisWithinGibbs,
    diagnose,
    run_chains,
    to_inference_data,
)
from bayescal.mcmc.diagnostics import extended_length


def import_arviz() -> Any:
    """ArviZ without its once-a-day FutureWarning about its own 1.0 migration."""
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message=r"\s*ArviZ is undergoing a major refactor", category=FutureWarning
        )
        import arviz

    return arviz


def classical_rhat(chains: NDArray[np.float64]) -> float:
    """Potential scale reduction of (n_chains, n_draws) draws, no splitting (BDA3, 11.4)."""
    n = chains.shape[1]
    within = chains.var(axis=1, ddof=1).mean()
    between = n * chains.mean(axis=1).var(ddof=1)
    var_plus = (n - 1) / n * within + between / n
    return float(np.sqrt(var_plus / within))


def split(chains: NDArray[np.float64]) -> NDArray[np.float64]:
    """First and last halves of each chain as separate chains (middle draw dropped if odd)."""
    half = chains.shape[1] // 2
    return np.concatenate([chains[:, :half], chains[:, -half:]], axis=0)


def split_rhat(chains: NDArray[np.float64]) -> float:
    """Classical split R-hat (BDA3, section 11.4)."""
    return classical_rhat(split(chains))


def rank_normalised_rhat(chains: NDArray[np.float64]) -> float:
    """Rank-normalised split R-hat: max of bulk and folded (Vehtari et al. 2021)."""

    def z_scale(values: NDArray[np.float64]) -> NDArray[np.float64]:
        ranks = stats.rankdata(values, method="average").reshape(values.shape)
        return stats.norm.ppf((ranks - 3.0 / 8.0) / (values.size + 1.0 / 4.0))

    halves = split(chains)
    folded = np.abs(halves - np.median(halves))
    return max(classical_rhat(z_scale(halves)), classical_rhat(z_scale(folded)))


def iid_chains(n_chains: int, n_draws: int, d: int, seed: int) -> NDArray[np.float64]:
    return np.random.default_rng(seed).normal(size=(n_chains, n_draws, d))


def test_well_mixed_chains_give_no_warning() -> None:
    result = diagnose(iid_chains(4, 1000, 2, seed=0), names=["k", "c"])
    assert result.ok
    assert result.warnings == ()
    assert isinstance(result, Diagnostics)
    assert result.names == ("k", "c")
    # Independent draws: R-hat within ~1 / sqrt(n) of 1, ESS near the 4000 draws.
    assert np.all(np.abs(result.rhat - 1.0) < 0.01)
    assert np.all(result.ess_bulk > 3000)
    assert np.all(result.ess_tail > 3000)
    # MCSE of the mean of 4000 independent N(0, 1) draws is 1 / sqrt(4000) = 0.0158. ArviZ
    # estimates it through an autocorrelation-based ESS, which for independent draws
    # scatters by 2 % (sd over 300 seeds) with extremes beyond 10 % (13 % here): 20 %.
    np.testing.assert_allclose(result.mcse_mean, 1 / np.sqrt(4000), rtol=0.2)


def test_chains_in_different_places_give_an_rhat_warning() -> None:
    draws = iid_chains(4, 1000, 2, seed=1)
    draws[:, :, 1] += np.array([0.0, 0.0, 0.0, 3.0])[:, None]  # chain 3 explores elsewhere
    result = diagnose(draws, names=["k", "tau"])
    assert not result.ok
    rhat_warnings = [w for w in result.warnings if w.startswith("R-hat")]
    assert len(rhat_warnings) == 1
    assert "'tau'" in rhat_warnings[0]
    assert f"{result.rhat[1]:.4f}" in rhat_warnings[0]
    assert result.rhat[1] > 1.2
    assert result.rhat[0] < 1.01


def test_arviz_rhat_matches_the_classical_formulas() -> None:
    az = import_arviz()
    rng = np.random.default_rng(2)
    # AR(1) chains (phi = 0.9) with slightly different means: R-hat noticeably above 1.
    draws = np.zeros((4, 2001))
    noise = rng.normal(size=draws.shape)
    for t in range(1, draws.shape[1]):
        draws[:, t] = 0.9 * draws[:, t - 1] + noise[:, t]
    draws += np.array([0.0, 0.3, -0.2, 0.5])[:, None]
    classical = split_rhat(draws)
    # Same formula, two implementations: agreement to round-off.
    assert az.rhat(draws, method="split") == pytest.approx(classical, rel=1e-12)
    # diagnose() reports the rank-normalised R-hat; recomputed here from the paper.
    reported = diagnose(draws[:, :, None]).rhat[0]
    assert reported == pytest.approx(rank_normalised_rhat(draws), rel=1e-12)
    # For near-Gaussian draws rank normalisation changes little: within 0.01.
    assert abs(reported - classical) < 0.01
    assert classical > 1.01


def test_too_few_draws_give_an_ess_warning() -> None:
    result = diagnose(iid_chains(4, 50, 1, seed=3), names=["lambda"])
    ess_warnings = [w for w in result.warnings if "ESS" in w]
    # 200 independent draws: both ESS about 200 < 400.
    assert any(w.startswith("bulk ESS of 'lambda'") for w in ess_warnings)
    assert any(w.startswith("tail ESS of 'lambda'") for w in ess_warnings)
    assert f"{result.ess_bulk[0]:.0f} < 400" in ess_warnings[0]


def test_frozen_chain_and_low_acceptance_are_reported_as_stuck() -> None:
    draws = iid_chains(4, 1000, 2, seed=4)
    draws[2, :, 0] = 0.7  # chain 2 never moves parameter 'a'
    acceptance = np.full((4, 2), 0.4)
    acceptance[1, 1] = 0.002  # chain 1 almost never accepts 'b'
    result = diagnose(draws, names=["a", "b"], acceptance=acceptance)
    assert any("chain 2 is stuck: 'a' never moved" in w and "0.7" in w for w in result.warnings)
    assert any("chain 1 is stuck: acceptance rate of 'b' is 0.0020" in w for w in result.warnings)


def test_all_chains_frozen_apart_is_not_a_silent_pass() -> None:
    draws = np.broadcast_to(np.array([0.0, 1.0, 2.0, 3.0])[:, None, None], (4, 500, 1)).copy()
    result = diagnose(draws, names=["theta"])
    assert np.isnan(result.rhat[0])
    assert np.isnan(result.ess_bulk[0])
    assert any("R-hat of 'theta' cannot be computed" in w for w in result.warnings)
    assert sum("is stuck" in w for w in result.warnings) == 4


def test_fixed_parameters_are_not_judged() -> None:
    draws = iid_chains(4, 1000, 2, seed=5)
    draws[:, :, 1] = 0.25
    acceptance = np.array([[0.4, np.nan]] * 4)
    result = diagnose(draws, names=["free", "fixed"], acceptance=acceptance)
    assert result.ok
    assert np.isnan(result.rhat[1])
    table = result.table()
    assert table.loc["free", "acceptance"] == pytest.approx(0.4)  # mean over chains
    assert np.isnan(table["acceptance"].to_numpy()[1])


def test_fewer_than_four_chains_warn() -> None:
    result = diagnose(iid_chains(2, 2000, 1, seed=6))
    assert any(w.startswith("only 2 chain(s)") for w in result.warnings)


def test_bad_input_raises_config_error() -> None:
    with pytest.raises(ConfigError, match=r"shape \(n_chains, n_draws >= 4, d\)"):
        diagnose(np.zeros((4, 100)))
    with pytest.raises(ConfigError, match="need 2 distinct parameter names"):
        diagnose(iid_chains(4, 10, 2, seed=0), names=["a", "a"])


@pytest.mark.parametrize("sampler", [MetropolisWithinGibbs(n_burn=1000), AdaptiveMetropolis()])
def test_sampled_chains_end_to_end(sampler: Any) -> None:
    chains = run_chains(sampler, standard_normal_2d, np.array([[-2.0, 2.0], [2.0, -2.0],
                        [0.0, 3.0], [3.0, 0.0]]), 3000, seed=9, names=["u", "v"],
                        backend="serial")  # fmt: skip
    result = diagnose(chains)
    assert result.ok, result.warnings
    assert result.acceptance is not None
    assert result.acceptance.shape == (4, 2)
    table = result.table()
    assert list(table.index) == ["u", "v"]
    assert {"mean", "sd", "r_hat", "ess_bulk", "ess_tail", "mcse_mean", "acceptance"} <= set(
        table.columns
    )
    idata: Any = to_inference_data(chains)
    assert set(idata.posterior.data_vars) == {"u", "v"}
    assert idata.posterior["u"].shape == (4, 3000)
    np.testing.assert_array_equal(idata.sample_stats["lp"].values, chains.log_density)
    assert idata.attrs["seed"] == 9


def standard_normal_2d(x: NDArray[np.float64]) -> float:
    return -0.5 * float(x @ x)


def test_failing_chains_grow_by_half_up_to_the_most() -> None:
    # the calibration's and the difference-process phase's common rule
    assert [extended_length(n, 8000) for n in (2000, 3000, 4500, 6750)] == [3000, 4500, 6750, 8000]
    assert extended_length(3, 10) == 5  # ceil(4.5)
    assert extended_length(1, 10) == 2  # at least one draw more
    assert extended_length(100, 130, growth=2.0) == 130


def test_each_statistic_is_one_arviz_call_over_every_parameter(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """R-hat, the ESS and the MCSE are computed once for all parameters (not once per
    parameter: nine parameters made the diagnostics nine times slower)."""
    import arviz as az

    calls: list[str] = []
    for name in ("rhat", "ess", "mcse"):
        real = getattr(az, name)
        monkeypatch.setattr(
            az, name, lambda *a, _real=real, _name=name, **k: calls.append(_name) or _real(*a, **k)
        )
    draws = np.random.default_rng(3).standard_normal((4, 500, 9))
    diag = diagnose(draws)
    assert sorted(calls) == ["ess", "ess", "mcse", "mcse", "rhat"]
    assert diag.ess_bulk.shape == (9,)
