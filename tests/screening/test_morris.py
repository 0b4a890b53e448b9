"""Morris elementary effects against functions whose effects are known exactly."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.errors import ConfigError
from bayescal.screening import morris_design, morris_indices, propose

pytest.importorskip("SALib", reason="screening needs SALib")

NAMES = ("linear", "square", "inert", "x", "y")


def _model(u: np.ndarray) -> np.ndarray:
    # 4 u0 (linear), u1² (non-linear), nothing from u2, an interaction u3 u4
    return 4.0 * u[:, 0] + u[:, 1] ** 2 + 2.0 * u[:, 3] * u[:, 4]


def test_design_is_trajectories_on_the_grid() -> None:
    design = morris_design(NAMES, trajectories=6, levels=4, seed=3)
    assert design.unit.shape == (6 * (len(NAMES) + 1), len(NAMES))
    np.testing.assert_allclose(design.unit * 3, np.round(design.unit * 3), atol=1e-12)
    # within a trajectory consecutive points differ in exactly one parameter, by 2/3
    steps = np.diff(design.unit.reshape(6, len(NAMES) + 1, len(NAMES)), axis=1)
    assert np.all(np.count_nonzero(np.abs(steps) > 1e-12, axis=2) == 1)
    np.testing.assert_allclose(np.abs(steps).sum(axis=2), 2.0 / 3.0)
    again = morris_design(NAMES, trajectories=6, levels=4, seed=3)
    np.testing.assert_array_equal(again.unit, design.unit)


def test_effects_of_known_functions() -> None:
    design = morris_design(NAMES, trajectories=20, levels=4, seed=11)
    ix = morris_indices(design, _model(design.unit), "y", bootstrap=200, seed=1)
    # a linear effect is the same in every trajectory: mu* = |mu| = 4, sigma = 0
    assert ix.mu_star[0] == pytest.approx(4.0, abs=1e-9)
    assert ix.sigma[0] == pytest.approx(0.0, abs=1e-9)
    assert ix.mu_star[2] == pytest.approx(0.0, abs=1e-12)
    # u² from u to u + 2/3 on the 4-level grid: effect 2u + 2/3 with u in {0, 1/3}: 2/3 or 4/3
    assert 2 / 3 - 1e-9 <= ix.mu_star[1] <= 4 / 3 + 1e-9
    assert ix.sigma[1] > 0
    # the interaction: effect of u3 is 2 u4, so sigma > 0 and mu* = mean(2 u4) ~ 1
    assert ix.sigma[3] > 0.3
    assert list(ix.ranks[[0, 2]]) == [1, 5]
    assert np.all(ix.mu_star_conf >= 0)


def test_failed_runs_drop_their_trajectories() -> None:
    design = morris_design(NAMES, trajectories=5, levels=4, seed=2)
    y = _model(design.unit)
    y[7] = np.nan  # a run of the second trajectory failed
    ix = morris_indices(design, y, "y", bootstrap=50)
    assert ix.trajectories == 4
    assert ix.mu_star[0] == pytest.approx(4.0)
    y[: 4 * (len(NAMES) + 1)] = np.nan
    with pytest.raises(ConfigError, match="only 1 of 5 Morris trajectories"):
        morris_indices(design, y, "y", bootstrap=50)


def test_proposal_keeps_what_matters_for_any_output() -> None:
    design = morris_design(NAMES, trajectories=10, levels=4, seed=5)
    first = morris_indices(design, _model(design.unit), "a", bootstrap=50)
    # a second output driven by the inert parameter only
    second = morris_indices(design, design.unit[:, 2] * 1e-3, "b", bootstrap=50)
    proposal = propose([first, second], threshold=0.1)
    assert proposal.selected[0] in ("linear", "inert")
    assert set(proposal.selected) == {"linear", "square", "inert", "x", "y"} - {
        n for n in NAMES if proposal.score[n] < 0.1
    }
    assert "inert" in proposal.selected
    assert proposal.deciding["inert"] == "b"
    assert propose([first], threshold=0.5).selected[0] == "linear"
    capped = propose([first, second], threshold=0.01, max_parameters=2)
    assert len(capped.selected) == 2


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ConfigError, match="at least two parameters"):
        morris_design(["a"], trajectories=4, levels=4, seed=0)
    with pytest.raises(ConfigError, match="even number of levels"):
        morris_design(NAMES, trajectories=4, levels=3, seed=0)
