"""Posteriors leaning on a bound of their prior (calibration.bounds)."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.calibration.bounds import EDGE, LEAN_SHARE, MEANING, bound_leans, bound_warnings
from bayescal.design import UniformPrior


def _piled_at_upper(rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
    """A posterior truncated by the upper bound: half-normal below 1 with SD 0.05."""
    return 1.0 - np.abs(rng.normal(0.0, 0.05, size))


def test_a_posterior_as_flat_as_the_prior_is_not_flagged() -> None:
    rng = np.random.default_rng(0)
    # 20 posteriors of 400 draws each, spread uniformly over the prior: about 1 % of
    # the draws lie in each edge band, far below the 5 % that flags a bound.
    for _ in range(20):
        assert bound_leans(rng.random((2, 200, 3)), ["a", "b", "c"]) == ()


def test_a_posterior_piled_at_the_upper_bound_is_flagged_on_that_side_only() -> None:
    rng = np.random.default_rng(1)
    draws = np.stack([rng.random((4, 500)), _piled_at_upper(rng, (4, 500))], axis=-1)
    leans = bound_leans(draws, ["free", "piled"])
    assert [(lean.name, lean.side) for lean in leans] == [("piled", "upper")]
    # half-normal with SD 0.05: P(|z| < 0.01 / 0.05) = 0.16 of the draws near the bound
    assert leans[0].share == pytest.approx(0.16, abs=0.03)
    # the same posterior mirrored piles at the lower bound
    mirrored = bound_leans(1.0 - draws, ["free", "piled"])
    assert [(lean.name, lean.side) for lean in mirrored] == [("piled", "lower")]


def test_a_narrow_posterior_near_but_inside_a_bound_is_not_flagged() -> None:
    rng = np.random.default_rng(2)
    # mean 0.95, SD 0.01: the data fix the value, the bound does not cut it
    draws = rng.normal(0.95, 0.01, (4, 1000, 1))
    assert bound_leans(draws, ["k"]) == ()
    # mean 0.985, SD 0.01: a third of its draws is cut off by the bound
    assert bound_leans(np.clip(draws + 0.035, 0, 1), ["k"])[0].side == "upper"


def test_the_threshold_is_a_share_of_the_draws_in_the_edge_band() -> None:
    n = 1000
    inside = round(LEAN_SHARE * n)
    at_edge = np.full(n, 0.5)
    at_edge[:inside] = 1.0 - EDGE / 2
    assert bound_leans(at_edge[:, None], ["k"])[0].share == pytest.approx(LEAN_SHARE)
    at_edge[inside - 1] = 0.5
    assert bound_leans(at_edge[:, None], ["k"]) == ()
    with pytest.raises(ValueError, match="2 parameters"):
        bound_leans(at_edge[:, None], ["k", "j"])


def test_the_warning_names_the_bound_its_unit_and_what_it_means() -> None:
    rng = np.random.default_rng(3)
    priors = {
        "k_cb": UniformPrior(0.05, 0.2, unit="W/(m·K)"),
        "cp_cb": UniformPrior(500.0, 1500.0, unit="J/(kg·K)"),
    }
    draws = np.stack([_piled_at_upper(rng, (2, 500)), rng.random((2, 500))], axis=-1)
    (text,) = bound_warnings(draws, priors, phase="calibration: ")
    assert text.startswith("calibration: k_cb leans on the upper bound of its prior (0.2 W/(m·K))")
    assert MEANING in text
    assert "fitting constant" in text
    assert bound_warnings(rng.random((2, 500, 2)), priors) == ()


def test_a_parameter_held_on_a_bound_is_not_flagged() -> None:
    # reuse_screening holds a screened-out input at its nominal value, which may lie on
    # a bound: all its draws sit in the edge band, yet it was never free to lean
    rng = np.random.default_rng(5)
    draws = np.stack(
        [np.zeros((4, 300)), _piled_at_upper(rng, (4, 300)), np.full((4, 300), 0.3)], axis=-1
    )
    leans = bound_leans(draws, ["held", "piled", "inside"])
    assert [(lean.name, lean.side) for lean in leans] == [("piled", "upper")]
