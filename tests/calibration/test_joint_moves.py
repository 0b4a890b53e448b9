"""``[calibration] moves = "joint"``: which coordinates move together, and the same posterior.

* :func:`default_sampler` puts theta*, every ``lambda*``, AR(1) ``phi`` and
  discrepancy ``r`` in the joint block for a calibration with an observation
  model (``lambda`` keeps its own move), theta* alone for the paper's one white
  output (whose batched likelihood moves theta* jointly only); ``"gibbs"`` is the
  sampler as before.
* On the small virtual wall with AR(1) errors, calibrations with ``"joint"`` and
  ``"gibbs"`` moves agree: every coordinate's posterior mean within 4 combined
  Monte Carlo standard errors (ArviZ), and the joint calibration passes its
  diagnostics (marked slow); with one white output, lockstep chains take the draws
  of serial ones.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from bayescal.calibration import calibrate
from bayescal.calibration.target import build_target, default_sampler
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import ObservationModel
from bayescal.errors import ConfigError
from bayescal.mcmc.diagnostics import import_arviz
from virtual_wall import VirtualExperiment

Wall = tuple[VirtualExperiment, Assembled, Emulator]
N_SE = 4.0


def _ar1(a: Assembled) -> ObservationModel:
    obs = a.observations
    assert obs is not None
    return ObservationModel((dataclasses.replace(obs.outputs[0], model="ar1"),), obs.k, obs.y_star)


def test_default_sampler_builds_the_joint_block(small_wall: Wall) -> None:
    _, a, em = small_wall
    priors = list(a.priors.values())
    coupled = build_target(em, a.w_star, a.lam_star_prior, priors, observations=_ar1(a))
    t, d = coupled.t, coupled.d
    assert coupled.aux_names == ("lambda", "lambda_star", "phi")
    joint = default_sampler(coupled, 100, "joint")
    assert joint.joint == (*range(t), t + 1, t + 2)
    assert joint.joint_after_burn == d - 1
    gibbs = default_sampler(coupled, 100)
    assert gibbs.joint == tuple(range(t))
    assert gibbs.joint_after_burn == 0
    plain = build_target(em, a.w_star, a.lam_star_prior, priors)
    assert plain.plain
    assert default_sampler(plain, 100, "joint").joint == tuple(range(t))
    assert default_sampler(plain, 100, "joint").joint_after_burn == t
    with pytest.raises(ConfigError, match="'gibbs' or 'joint'"):
        default_sampler(plain, 100, "all")  # type: ignore[arg-type]


@pytest.mark.slow  # two AR(1) calibrations of 4 x 1400 sweeps: about half a minute
def test_joint_and_gibbs_moves_sample_the_same_posterior(small_wall: Wall) -> None:
    az = import_arviz()
    _, a, em = small_wall
    obs = _ar1(a)
    posts = {
        moves: calibrate(
            em,
            a,
            n_chains=4,
            n_burn=400,
            n_draws=1000,
            seed=3,
            backend="serial",
            observations=obs,
            moves=moves,  # type: ignore[arg-type]
        )
        for moves in ("gibbs", "joint")
    }
    joint = posts["joint"]
    assert not joint.warnings, joint.warnings
    draws = {m: p.all_draws() for m, p in posts.items()}
    for k, name in enumerate(joint.all_names):
        values = {m: d[..., k] for m, d in draws.items()}
        se = math.hypot(*(float(az.mcse(v, method="mean")) for v in values.values()))
        diff = float(np.mean(values["joint"]) - np.mean(values["gibbs"]))
        assert abs(diff) < N_SE * se, (name, diff, se)


def test_joint_moves_of_one_white_output_are_the_same_in_lockstep(small_wall: Wall) -> None:
    """The batched likelihood's session moves theta* jointly several times a sweep: its
    chains take the draws of serial ones."""
    _, a, em = small_wall
    posts = [
        calibrate(em, a, n_chains=4, n_burn=200, n_draws=300, seed=1, backend=b, moves="joint")
        for b in ("serial", "vectorised")
    ]
    np.testing.assert_array_equal(posts[0].unit_draws, posts[1].unit_draws)
    np.testing.assert_array_equal(posts[0].aux, posts[1].aux)
    t = len(a.parameter_names)
    for row in posts[1].acceptance:  # theta* shares the joint move's rate
        assert np.all(row[:t] == row[0])
        assert 0.05 < row[0] < 0.6
