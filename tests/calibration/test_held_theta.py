"""theta* held fixed (the catalogue model of ``bayescal compare``): the chains sample the
error model alone, theta* stays at the held values, and the diagnostics pass over it."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.calibration import cv
from bayescal.calibration.posterior import calibrate
from bayescal.calibration.target import build_target, default_sampler, hold_theta
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.errors import ConfigError
from virtual_wall import VirtualExperiment

Wall = tuple[VirtualExperiment, Assembled, Emulator]


def test_held_parameters_keep_their_values(small_wall: Wall) -> None:
    _, a, em = small_wall
    names = a.parameter_names
    values = {n: float(p.from_unit(0.3 + 0.2 * k)) for k, (n, p) in enumerate(a.priors.items())}
    post = calibrate(
        em, a, n_chains=4, n_burn=100, n_draws=150, seed=3, backend="vectorised",
        observations=a.observations, held=values,
    )  # fmt: skip
    want = np.array([values[n] for n in names])
    np.testing.assert_allclose(post.draws, np.broadcast_to(want, post.draws.shape), rtol=1e-12)
    # theta* did not move: NaN acceptance, no diagnostics of its own; the precisions moved
    t = len(names)
    assert np.all(np.isnan(post.acceptance[:, :t]))
    assert np.all(post.acceptance[:, t:] > 0.05)
    assert not any(n in w for w in post.warnings for n in names)
    assert np.std(post.aux[..., 0]) > 0.0
    assert np.std(post.aux[..., 1]) > 0.0
    # the leave-period-out machinery takes it as any posterior: few effective parameters
    scores = cv.leave_period_out(em, a.observations, post, draws_per_chain=50)
    assert np.all(np.isfinite(scores.pointwise))
    assert 0.0 < scores.p_loo < t + 2.0
    # ... and a refit holds theta* too
    unit = np.array([0.3 + 0.2 * k for k in range(t)])
    _, refit, _ = cv.refit_period(
        em, a.observations, dict(a.priors), 0, n_chains=4, n_burn=60, n_draws=60, seed=1,
        backend="serial", draws_per_chain=20, held=unit,
    )  # fmt: skip
    np.testing.assert_allclose(refit.unit_draws, np.broadcast_to(unit, refit.unit_draws.shape))


def test_hold_theta_frees_only_the_error_model(small_wall: Wall) -> None:
    _, a, em = small_wall
    target = build_target(em, a.w_star, a.lam_star_prior, list(a.priors.values()))
    sampler = default_sampler(target, 50, "joint")
    starts = np.full((4, target.d), 0.5)
    held, x0 = hold_theta(sampler, starts, [0.1, 1.0])
    assert tuple(held.fixed or ()) == (0, 1)
    assert held.joint == ()
    assert not held.screen
    np.testing.assert_array_equal(x0[:, :2], [[0.1, 1.0]] * 4)
    np.testing.assert_array_equal(starts, 0.5)  # the given starts are not changed
    with pytest.raises(ConfigError, match="outside the prior bounds"):
        hold_theta(sampler, starts, [0.1, 1.2])
    with pytest.raises(ConfigError, match="hold every parameter or none"):
        calibrate(em, a, held={a.parameter_names[0]: 0.1})
    with pytest.raises(ConfigError, match="sampler 'mwg' only"):
        calibrate(em, a, held=dict.fromkeys(a.parameter_names, 0.1), sampler="nuts")


def test_some_parameters_held_the_others_sampled(small_wall: Wall) -> None:
    """``fixed`` (``[design] reuse_screening``'s screened-out inputs): one coordinate held,
    the other sampled; a NaN in ``hold_theta``'s values leaves its coordinate free."""
    _, a, em = small_wall
    names = a.parameter_names
    keep = names[1]
    value = float(a.priors[keep].from_unit(0.4))
    post = calibrate(
        em, a, n_chains=4, n_burn=100, n_draws=150, seed=3, backend="vectorised",
        observations=a.observations, fixed={keep: value},
    )  # fmt: skip
    np.testing.assert_allclose(post.draws[..., 1], value, rtol=1e-12)
    assert np.all(np.isnan(post.acceptance[:, 1]))
    assert np.all(post.acceptance[:, 0] > 0.05)
    assert np.std(post.draws[..., 0]) > 0.0
    with pytest.raises(ConfigError, match="cannot hold"):
        calibrate(em, a, n_chains=2, n_burn=10, n_draws=10, fixed={"nope": 1.0})
    target = build_target(em, a.w_star, a.lam_star_prior, list(a.priors.values()))
    sampler = default_sampler(target, 50, "joint")
    held, x0 = hold_theta(sampler, np.full((4, target.d), 0.5), [np.nan, 0.4])
    assert tuple(held.fixed or ()) == (1,)
    assert 1 not in held.joint
    assert 0 in held.joint
    np.testing.assert_array_equal(x0[:, :2], [[0.5, 0.4]] * 4)
