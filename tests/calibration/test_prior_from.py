"""A previous posterior as the prior: the logit-normal density and its use in the target.

* :class:`~bayescal.design.LogitNormal` against scipy's multivariate normal of
  ``logit(u)`` with the Jacobian written out, and its marginal
  (:class:`~bayescal.design.PosteriorPrior`) integrating to 1;
* the fit recovering a known density from its draws;
* the calibration target with such priors: the batched posterior's proposals
  (coordinate by coordinate, with the joint density added) equal the scalar
  posterior row by row, and ``-inf`` outside the bounds;
* the spec round trip of the stores.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, special, stats

from bayescal.calibration.posterior import START_MARGIN, warm
from bayescal.calibration.priors import ThetaPriors
from bayescal.calibration.target import CalibrationPosterior
from bayescal.design import (
    LogitNormal,
    PosteriorPrior,
    UniformPrior,
    fit_logit_normal,
    prior_from_spec,
)
from bayescal.errors import ConfigError
from random_density import random_density

MEAN = (0.3, -0.8)
COV = ((0.5, 0.3), (0.3, 0.4))
JOINT = LogitNormal(("a", "b"), MEAN, COV, "elsewhere/out")


def test_logit_normal_is_the_gaussian_of_logit_u_with_its_jacobian() -> None:
    rng = np.random.default_rng(1)
    u = rng.uniform(0.01, 0.99, (50, 2))
    z = special.logit(u)
    want = stats.multivariate_normal(MEAN, COV).logpdf(z) - np.sum(np.log(u * (1 - u)), axis=1)
    np.testing.assert_allclose(JOINT.logpdf_unit(u), want, rtol=1e-12)
    outside = np.array([[0.0, 0.5], [0.5, 1.0], [-0.1, 0.5]])
    assert np.all(np.isneginf(JOINT.logpdf_unit(outside)))


def test_a_share_of_the_joint_is_its_marginal_and_integrates_to_one() -> None:
    for index in (0, 1):
        prior = PosteriorPrior(2.0, 5.0, joint=JOINT, index=index)
        total, _ = integrate.quad(lambda x, p=prior: math.exp(float(p.logpdf(x))), 2.0, 5.0)
        assert total == pytest.approx(1.0, abs=1e-8)
        draws = prior.sample_unit(np.random.default_rng(index), 20_000)
        z = special.logit(draws)
        se = math.sqrt(COV[index][index] / z.size)
        assert abs(z.mean() - MEAN[index]) < 4 * se


def test_the_fit_recovers_a_known_density_from_its_draws() -> None:
    rng = np.random.default_rng(2)
    z = rng.multivariate_normal(MEAN, COV, 40_000)
    fitted = fit_logit_normal(("a", "b"), special.expit(z), "x")
    np.testing.assert_allclose(fitted.mean, MEAN, atol=0.02)
    np.testing.assert_allclose(fitted.cov, COV, atol=0.02)
    with pytest.raises(ConfigError, match="prior bounds"):
        fit_logit_normal(("a",), np.array([[0.2], [1.0]]))


def _posterior() -> CalibrationPosterior:
    # the joint over parameters 2 and 0 (in that order), parameter 1 uniform
    priors = [
        PosteriorPrior(0.0, 1.0, joint=JOINT, index=1),
        UniformPrior(0.0, 2.0),
        PosteriorPrior(-1.0, 1.0, joint=JOINT, index=0),
    ]
    return CalibrationPosterior(random_density(), priors, (5.0, 5.0), (3.0, 1.5))


def test_the_target_adds_the_joint_density_in_every_form() -> None:
    target = _posterior()
    batched = _posterior().lockstep()
    rng = np.random.default_rng(3)
    start = np.column_stack([rng.uniform(0.05, 0.95, (6, 3)), rng.uniform(0.5, 2.0, (6, 2))])
    got = batched.start(start)
    want = np.array([target(row) for row in start])
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # the prior: the joint at (u_2, u_0), not the product of the marginals
    u = start[:, :3]
    joint = JOINT.logpdf_unit(u[:, [2, 0]])
    prior = np.array([target.log_prior(row) for row in start]) - np.array(
        [target.log_prior(np.r_[0.5, 0.5, 0.5, row[3:]]) for row in start]
    )
    np.testing.assert_allclose(prior, joint - JOINT.logpdf_unit(np.array([[0.5, 0.5]]))[0])
    for moved in (0, 1, 2, (0, 2)):
        points = start.copy()
        columns = moved if isinstance(moved, tuple) else (moved,)
        for k in columns:
            points[:, k] = rng.uniform(-0.05, 1.0, 6)
        proposed = batched.propose(points, moved)
        expected = np.array([target(row) for row in points])
        finite = np.isfinite(expected)
        assert np.array_equal(finite, np.isfinite(proposed))
        np.testing.assert_allclose(proposed[finite], expected[finite], rtol=1e-11)
        batched.commit(np.ones(6, dtype=bool))
        start = points if finite.all() else start
        if not finite.all():
            batched.start(start)


def test_theta_priors_refuse_a_joint_with_a_missing_share() -> None:
    with pytest.raises(ConfigError, match="needs its share"):
        ThetaPriors((PosteriorPrior(0.0, 1.0, joint=JOINT, index=0), UniformPrior(0.0, 1.0)))


def test_the_spec_round_trip_keeps_the_joint() -> None:
    prior = PosteriorPrior(2.0, 5.0, unit="K", description="x", joint=JOINT, index=1)
    again = prior_from_spec(**prior.spec())
    assert again == prior
    assert isinstance(again, PosteriorPrior)
    assert again.joint == JOINT


def test_given_starts_replace_theta_only_clipped_inside_the_bounds() -> None:
    default = np.arange(12.0).reshape(3, 4) / 20.0
    given = np.array([[0.0, 0.3], [1.2, np.nan], [0.5, 0.7]])
    got = warm(default, given, 2)
    np.testing.assert_array_equal(got[:, 2:], default[:, 2:])  # the precisions as by default
    np.testing.assert_array_equal(
        got[:, :2], [[START_MARGIN, 0.3], [1 - START_MARGIN, default[1, 1]], [0.5, 0.7]]
    )
    assert warm(default, None, 2) is default
    with pytest.raises(ConfigError, match="starts must be"):
        warm(default, given[:2], 2)
