"""Priors, the Latin-hypercube design, and design files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import integrate, stats

from bayescal.design import (
    BetaPrior,
    Design,
    UniformPrior,
    latin_hypercube,
    log_gamma,
    log_gamma_array,
    log_gamma_of_log,
    prior_from_spec,
)
from bayescal.errors import ConfigError
from bayescal.store.design import load_design, save_design

PRIORS = {
    "k": UniformPrior(0.5, 2.0),
    "rho_c": BetaPrior(1.0e6, 3.0e6, a=2.0, b=5.0),
    "r_si": UniformPrior(0.1, 0.2),
}


def test_uniform_logpdf() -> None:
    prior = UniformPrior(2.0, 6.0)
    x = np.array([1.9, 2.0, 3.0, 6.0, 6.1])
    expected = np.array([-np.inf, -math.log(4), -math.log(4), -math.log(4), -np.inf])
    np.testing.assert_allclose(prior.logpdf(x), expected, rtol=1e-15)
    np.testing.assert_array_equal(prior.logpdf_unit([-0.1, 0.0, 0.5, 1.0]), [-np.inf, 0, 0, 0])


@pytest.mark.parametrize(("shape", "rate"), [(5.0, 5.0), (0.5, 2.0), (1.0, 0.1)])
def test_the_three_forms_of_the_gamma_log_density_agree(shape: float, rate: float) -> None:
    """``log_gamma`` (one value), ``log_gamma_array`` and ``log_gamma_of_log``: one density,
    scipy's up to its constant, ``-inf`` where the value is not positive."""
    x = np.array([0.01, 0.5, 1.0, 3.7, 40.0])
    ref = stats.gamma(shape, scale=1.0 / rate).logpdf(x)
    const = shape * math.log(rate) - math.lgamma(shape)
    np.testing.assert_allclose([log_gamma(v, shape, rate) for v in x], ref - const, rtol=1e-12)
    # equal value for value, on the masked path (a value <= 0 present) and the plain one
    mixed = np.array([-1.0, 0.0, *x])
    expected = [log_gamma(float(v), shape, rate) for v in mixed]
    np.testing.assert_array_equal(log_gamma_array(mixed, shape, rate), expected)
    np.testing.assert_array_equal(log_gamma_array(x, shape, rate), expected[2:])
    np.testing.assert_allclose(
        [log_gamma_of_log(math.log(v), shape, rate) for v in x], expected[2:], rtol=1e-12
    )
    # one (shape, rate) pair per column
    table = np.column_stack([x, 2.0 * x])
    both = log_gamma_array(table, [shape, 2.0], [rate, 1.0])
    np.testing.assert_array_equal(both[:, 1], [log_gamma(2.0 * v, 2.0, 1.0) for v in x])


@pytest.mark.parametrize(("a", "b"), [(2.0, 5.0), (0.5, 0.5), (1.0, 3.0), (1.0, 1.0)])
def test_beta_logpdf_matches_scipy(a: float, b: float) -> None:
    prior = BetaPrior(-1.0, 3.0, a=a, b=b)
    x = np.linspace(-0.9, 2.9, 9)
    reference = stats.beta(a, b, loc=-1.0, scale=4.0).logpdf(x)
    # rtol 1e-12: both are closed-form log densities, differences are rounding only.
    np.testing.assert_allclose(prior.logpdf(x), reference, rtol=1e-12)
    u = (x + 1.0) / 4.0
    np.testing.assert_allclose(prior.logpdf_unit(u), stats.beta(a, b).logpdf(u), rtol=1e-12)
    assert prior.logpdf(np.array([-1.5, 3.5])).tolist() == [-np.inf, -np.inf]


def test_beta_density_integrates_to_one() -> None:
    prior = BetaPrior(10.0, 30.0, a=3.0, b=2.0)
    total, error = integrate.quad(lambda x: math.exp(prior.logpdf(x)), 10.0, 30.0)
    # 1e-9: quad's own error estimate on this smooth polynomial density is far smaller.
    assert total == pytest.approx(1.0, abs=1e-9)
    assert error < 1e-9


def test_beta_samples_follow_the_distribution() -> None:
    prior = BetaPrior(0.0, 1.0, a=2.0, b=5.0)
    draws = prior.sample_unit(np.random.default_rng(42), 20_000)
    result = stats.kstest(draws, stats.beta(2.0, 5.0).cdf)
    # p > 1e-3: a false alarm on a correct sampler has probability 1e-3 (fixed seed anyway).
    assert result.pvalue > 1e-3


@given(st.floats(0.0, 1.0), st.floats(-1e3, 1e3), st.floats(1e-3, 1e3))
def test_unit_round_trip(u: float, lower: float, width: float) -> None:
    prior = UniformPrior(lower, lower + width)
    # 1e-9 * scale: two affine maps, a few ulps of the larger of |lower| and width.
    scale = max(abs(lower), width, 1.0)
    assert float(prior.to_unit(prior.from_unit(u))) * width == pytest.approx(
        u * width, abs=1e-9 * scale
    )


@pytest.mark.parametrize(
    ("factory", "message"),
    [
        (lambda: UniformPrior(1.0, 1.0), "lower < upper"),
        (lambda: UniformPrior(2.0, 1.0), "lower < upper"),
        (lambda: UniformPrior(float("nan"), 1.0), "must be finite"),
        (lambda: UniformPrior("x", 1.0), "must be a number"),
        (lambda: BetaPrior(0.0, 1.0, a=0.0, b=1.0), "shape a must be > 0"),
        (lambda: BetaPrior(0.0, 1.0, a=1.0, b=-2.0), "shape b must be > 0"),
    ],
)
def test_prior_validation(factory, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        factory()


def test_prior_from_spec() -> None:
    assert prior_from_spec("uniform", 0, 1) == UniformPrior(0.0, 1.0)
    assert prior_from_spec("beta", 0, 1, a=2, b=3) == BetaPrior(0.0, 1.0, 2.0, 3.0)
    with pytest.raises(ConfigError, match="needs both shape parameters"):
        prior_from_spec("beta", 0, 1, a=2)
    with pytest.raises(ConfigError, match="takes no shape parameters"):
        prior_from_spec("uniform", 0, 1, a=2, b=2)
    with pytest.raises(ConfigError, match="unknown prior distribution 'normal'"):
        prior_from_spec("normal", 0, 1)


@pytest.mark.parametrize("optimization", [None, "random-cd"])
def test_latin_hypercube_has_one_point_per_stratum(optimization) -> None:
    runs = 20
    design = latin_hypercube(PRIORS, runs, seed=3, optimization=optimization)
    assert design.unit.shape == (runs, 3)
    assert design.names == ("k", "rho_c", "r_si")
    for j in range(3):
        strata = np.floor(design.unit[:, j] * runs).astype(int)
        assert sorted(strata) == list(range(runs))  # the defining LHS property
    # The physical design spans the bounds linearly, whatever the prior's shape.
    for j, prior in enumerate(PRIORS.values()):
        expected = prior.lower + design.unit[:, j] * (prior.upper - prior.lower)
        np.testing.assert_allclose(design.values[:, j], expected, rtol=1e-15)
        assert np.all((design.values[:, j] >= prior.lower) & (design.values[:, j] <= prior.upper))


def test_latin_hypercube_lloyd_and_reproducibility() -> None:
    lloyd = latin_hypercube(PRIORS, 12, seed=1, optimization="lloyd")
    assert np.all((lloyd.unit >= 0) & (lloyd.unit <= 1))
    again = latin_hypercube(PRIORS, 12, seed=1, optimization="lloyd")
    np.testing.assert_array_equal(lloyd.unit, again.unit)
    other = latin_hypercube(PRIORS, 12, seed=2, optimization="lloyd")
    assert not np.array_equal(lloyd.unit, other.unit)
    assert (lloyd.seed, lloyd.optimization) == (1, "lloyd")


def test_latin_hypercube_rejects_bad_requests() -> None:
    with pytest.raises(ConfigError, match="needs at least 5 runs, got runs=4"):
        latin_hypercube(PRIORS, 4, seed=0)
    with pytest.raises(ConfigError, match="unknown design optimization 'maximin'"):
        latin_hypercube(PRIORS, 10, seed=0, optimization="maximin")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="'lloyd' needs at least 2 parameters"):
        latin_hypercube({"k": UniformPrior(0, 1)}, 10, seed=0, optimization="lloyd")
    with pytest.raises(ConfigError, match="at least one calibration parameter"):
        latin_hypercube({}, 10, seed=0)
    with pytest.raises(ConfigError, match="seed must be a non-negative integer"):
        latin_hypercube(PRIORS, 10, seed=-1)


@pytest.mark.parametrize("suffix", [".json", ".csv"])
def test_save_load_round_trip(tmp_path: Path, suffix: str) -> None:
    design = latin_hypercube(PRIORS, 9, seed=11, optimization="random-cd")
    path = save_design(design, tmp_path / f"design{suffix}")
    back = load_design(path)
    np.testing.assert_array_equal(back.unit, design.unit)  # exact: floats written in full
    np.testing.assert_array_equal(back.values, design.values)
    assert back.priors == design.priors
    assert (back.seed, back.optimization) == (11, "random-cd")
    with pytest.raises(ConfigError, match=r"must end in \.json or \.csv"):
        save_design(design, tmp_path / "design.xlsx")


def test_to_frame_and_rows() -> None:
    design = latin_hypercube(PRIORS, 6, seed=5)
    frame = design.to_frame()
    assert list(frame.columns) == ["k", "rho_c", "r_si"]
    assert frame.index.name == "run"
    np.testing.assert_array_equal(frame.to_numpy(), design.values)
    assert design.row(2) == dict(zip(design.names, design.values[2].tolist(), strict=True))


def test_from_values() -> None:
    values = np.array([[1.0, 2.0e6, 0.15], [2.0, 1.0e6, 0.1]])
    design = Design.from_values(PRIORS, values)
    np.testing.assert_allclose(design.unit, [[1 / 3, 0.5, 0.5], [1.0, 0.0, 0.0]], rtol=1e-14)
    np.testing.assert_allclose(design.values, values, rtol=1e-15)
    with pytest.raises(ConfigError, match=r"\['k'\] lie outside their prior bounds"):
        Design.from_values(PRIORS, [[2.5, 2.0e6, 0.15]])
    with pytest.raises(ConfigError, match=r"shape \(runs, 3\), got \(1, 2\)"):
        Design.from_values(PRIORS, [[1.0, 2.0]])


def test_prior_carries_unit_and_description_through_its_spec() -> None:
    prior = prior_from_spec(
        "beta", 0.08, 0.16, 1.0, 2.0, unit="W/(m·K)", description="conductivity of the blocks"
    )
    spec = prior.spec()
    assert (spec["unit"], spec["description"]) == ("W/(m·K)", "conductivity of the blocks")
    assert prior_from_spec(**spec) == prior
    # Without them the spec stays as the study file writes a prior.
    assert set(UniformPrior(0.0, 1.0).spec()) == {"distribution", "lower", "upper"}
