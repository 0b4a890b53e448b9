"""Identifiability: contraction, correlation and principal directions on known posteriors."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.calibration.identifiability import identifiability, moves_hint
from bayescal.calibration.posterior import Posterior
from bayescal.design import UniformPrior


def _posterior(draws: np.ndarray, priors: dict[str, UniformPrior]) -> Posterior:
    unit = np.stack([p.to_unit(draws[..., k]) for k, p in enumerate(priors.values())], axis=-1)
    chains, n = draws.shape[:2]
    rng = np.random.default_rng(0)
    return Posterior.build(
        names=list(priors),
        priors=priors,
        unit_draws=unit,
        lam=rng.uniform(1.0, 2.0, (chains, n)),
        lam_star=rng.uniform(1.0, 2.0, (chains, n)),
        log_density=np.zeros((chains, n)),
        acceptance=np.full((chains, len(priors) + 2), 0.4),
    )


def test_a_product_fixed_and_a_split_left_open_are_told_apart() -> None:
    # Two conductivities in series: the data fix their product (in log terms a sum),
    # not their ratio, which stays as spread as under the prior.
    priors = {"k_a": UniformPrior(0.5, 2.0), "k_b": UniformPrior(0.5, 2.0)}
    rng = np.random.default_rng(1)
    n = 4 * 2000
    k_a = rng.uniform(0.5, 2.0, n)  # as spread as under the prior
    k_b = np.exp(-np.log(k_a) + rng.normal(0.0, 0.002, n))  # k_a k_b = 1: sharp
    draws = np.column_stack([k_a, k_b]).reshape(4, -1, 2)
    ident = identifiability(_posterior(draws, priors))
    sharp, loose = ident.directions  # eigenvalues ascending
    assert sharp.ratio < 0.01
    assert loose.ratio > 1.0  # along the ridge the posterior reaches the prior's corners
    # The sharp direction is k_a x k_b (equal exponents), the loose one k_a / k_b.
    np.testing.assert_allclose(sharp.exponents, [1.0, 1.0], atol=0.01)
    np.testing.assert_allclose(np.sort(loose.exponents), [-1.0, 1.0], atol=0.01)
    assert ident.correlation[0, 1] == pytest.approx(-1.0, abs=0.01)
    lines = ident.lines()
    assert lines[0].startswith("the data fix ")
    assert "k_a^1.00 x k_b^1.00" in lines[0] or "k_b^1.00 x k_a^1.00" in lines[0]
    # Neither parameter alone is pinned down: nothing learnt about either by itself.
    assert np.all(np.abs(ident.contraction) < 0.1)
    assert ident.lines()[1].startswith("unidentified: ")


def test_independent_sharp_and_flat_parameters() -> None:
    priors = {"a": UniformPrior(1.0, 2.0), "b": UniformPrior(-1.0, 1.0)}
    rng = np.random.default_rng(2)
    a = rng.normal(1.5, 0.001, 8000)
    b = rng.uniform(-1.0, 1.0, 8000)  # the prior itself: nothing learnt
    ident = identifiability(_posterior(np.column_stack([a, b]).reshape(4, -1, 2), priors))
    assert ident.log_scale == (True, False)  # b may be negative: linear scale
    assert ident.contraction[0] > 0.99
    assert abs(ident.contraction[1]) < 0.05  # Monte Carlo error of a variance ratio
    assert "unidentified: +1.00 b" in ident.lines()[1]


def _random_walk(rng: np.random.Generator, n: int, step: float) -> np.ndarray:
    """A slowly mixing chain: a reflected random walk in [0.55, 1.95]."""
    x = 1.25 + np.cumsum(rng.normal(0.0, step, n))
    return 1.25 + 0.7 * np.sin((x - 1.25) / 0.7 * np.pi / 2)


def test_moves_hint_names_the_correlated_pair_of_a_slow_calibration() -> None:
    priors = {"k_a": UniformPrior(0.5, 2.0), "k_b": UniformPrior(0.5, 2.0)}
    rng = np.random.default_rng(3)
    # slow chains along a ridge k_a k_b = 1.5 (correlation -1 on the log scale)
    k_a = np.stack([_random_walk(rng, 500, 0.01) for _ in range(4)])
    k_b = 1.5 / k_a * np.exp(rng.normal(0.0, 0.01, k_a.shape))
    slow = _posterior(np.stack([k_a, k_b], axis=-1), priors)
    assert slow.warnings  # R-hat and ESS fail
    hint = moves_hint(slow)
    assert hint is not None
    assert hint.startswith("k_a and k_b are correlated in the posterior (-0.9")
    assert 'moves = "joint"' in hint
    # the same slow chains without the ridge: no hint (the moves are not to blame)
    k_c = np.stack([_random_walk(rng, 500, 0.01) for _ in range(4)])
    apart = _posterior(np.stack([k_a, k_c], axis=-1), priors)
    assert apart.warnings
    assert moves_hint(apart) is None
    # a well-mixed ridge: no hint either (nothing failed)
    k_a = rng.uniform(0.8, 1.8, (4, 2000))
    mixed = _posterior(np.stack([k_a, 1.5 / k_a], axis=-1), priors)
    assert not mixed.warnings
    assert moves_hint(mixed) is None
