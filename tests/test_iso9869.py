"""ISO 9869-1's average method against walls whose resistance is known.

References: a steady wall (flux = ΔT / R exactly), the built-in wall under a
daily cycle (its periodic state has daily mean flux = daily mean ΔT / R, and from
a steady start the error decays as 1/D: the heat the wall stores once), and
series built by hand whose cumulative R, and so the conditions, are worked out
in the comments.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.iso9869 import R_SE, R_SI, average_method, u_value
from bayescal.simulators.base import Forcing
from virtual_wall import PAPER_TRUTH, PER_DAY, STEP, paper_wall


def test_surface_resistances_are_iso_6946s() -> None:
    assert (R_SI, R_SE) == (0.13, 0.04)
    assert u_value(2.0) == pytest.approx(1.0 / 2.17)
    assert np.isnan(u_value(-1.0))


def test_a_steady_wall_gives_its_resistance_every_day() -> None:
    r_true, days = 3.2, 6
    n = days * PER_DAY + 7  # a trailing part day is not used
    t_in, t_out = np.full(n, 21.0), np.full(n, -4.0)
    am = average_method(t_in, t_out, (t_in - t_out) / r_true, PER_DAY)
    assert am.days.tolist() == [1, 2, 3, 4, 5, 6]
    np.testing.assert_allclose(am.r, r_true, rtol=1e-13)
    np.testing.assert_allclose(am.u, 1.0 / (0.13 + r_true + 0.04), rtol=1e-13)
    assert am.duration.tolist() == [False, False, True, True, True, True]
    assert am.stable.tolist() == [False] + [True] * 5  # no R 24 h before day 1
    assert am.first_last.tolist() == [False] + [True] * 5  # INT(2/3) = 0 days on day 1
    assert am.first_converged == 3


def _cycle(days: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The paper's wall under a daily cycle of the outside face, from a steady start."""
    wall = paper_wall()
    n = days * PER_DAY
    hours = np.arange(n) * STEP / 3600.0
    t_out = 2.0 + 6.0 * np.sin(2.0 * np.pi * (hours - 9.0) / 24.0)
    t_in = np.full(n, 20.0)
    forcing = Forcing(STEP, {"temp_surf_out": t_out, "temp_surf_in": t_in})
    flux_out = -wall.simulate(PAPER_TRUTH, forcing)["heat_flux_in"]
    return t_in, t_out, flux_out, wall.derived(PAPER_TRUTH)["R_wall"]


def test_a_wall_in_its_periodic_state_gives_its_resistance_from_the_first_day() -> None:
    t_in, t_out, q, r_true = _cycle(30)
    warm = 20 * PER_DAY
    am = average_method(t_in[warm:], t_out[warm:], q[warm:], PER_DAY)
    np.testing.assert_allclose(am.r, r_true, rtol=1e-9)


def test_a_wall_from_a_steady_start_converges_as_one_over_the_days() -> None:
    t_in, t_out, q, r_true = _cycle(30)
    am = average_method(t_in, t_out, q, PER_DAY)
    error = am.r / r_true - 1.0
    assert abs(error[0]) > 0.10  # one day is far off: the wall is filling its store
    assert abs(error[-1]) < 0.01
    # The heat stored once, spread over D days: D x error is constant.
    scaled = error[[9, 19, 29]] * np.array([10, 20, 30])
    np.testing.assert_allclose(scaled, scaled[-1], rtol=0.02)
    assert am.first_converged is not None
    assert am.converged[am.first_converged - 1 :].all()


def test_conditions_on_a_series_built_by_hand() -> None:
    # One sample a day, ΔT = 10 K. q = 5, 5, 5, 5, 4, 4 W/m²:
    # cumulative R = 2, 2, 2, 2, 50/24 = 2.083, 60/28 = 2.143 (b: +4.2 %, +2.9 %: holds);
    # c with n = INT(2D/3) = 0, 1, 2, 2, 3, 4 days: R_first = 2 always, R_last = 2, 2, 2,
    # 30/14 = 2.143 (-6.7 %: fails), 40/18 = 2.222 (-10 %: fails).
    q = np.array([5.0, 5.0, 5.0, 5.0, 4.0, 4.0])
    am = average_method(np.full(6, 10.0), np.zeros(6), q, 1)
    np.testing.assert_allclose(am.r, [2, 2, 2, 2, 50 / 24, 60 / 28])
    np.testing.assert_allclose(am.r_last[1:], [2, 2, 2, 30 / 14, 40 / 18])
    assert am.stable.tolist() == [False, True, True, True, True, True]
    assert am.first_last.tolist() == [False, True, True, True, False, False]
    assert am.converged.tolist() == [False, False, True, True, False, False]
    assert am.first_converged == 3


def test_a_jump_fails_the_24_hour_condition_and_first_against_last_can_still_hold() -> None:
    # q = 5, 5, 5, 2, 5, 5, 5: R(4) = 40/17 = 2.353, +17.6 % on R(3) = 2; on day 7,
    # n = 4: days 1-4 and days 4-7 both give 40/17, and R(7) = 70/32 is -1.6 % on 60/27.
    q = np.array([5.0, 5.0, 5.0, 2.0, 5.0, 5.0, 5.0])
    am = average_method(np.full(7, 10.0), np.zeros(7), q, 1)
    assert not am.stable[3]
    assert am.stable[4:].all()
    assert am.r_first[6] == pytest.approx(40 / 17)
    assert am.r_last[6] == pytest.approx(40 / 17)
    assert am.first_last[6]
    assert am.converged[6]


def test_a_flux_the_wrong_way_never_converges() -> None:
    t_in, t_out = np.full(5, 20.0), np.zeros(5)
    am = average_method(t_in, t_out, np.full(5, -10.0), 1)
    assert am.stable[1:].all()  # R is steady ...
    assert (am.r == -2.0).all()
    assert np.isnan(am.u).all()
    assert am.first_converged is None  # ... but not positive


def test_missing_samples_are_left_out_of_both_sums() -> None:
    t_in, t_out = np.full(4, 20.0), np.zeros(4)
    q = np.array([10.0, np.nan, 10.0, 10.0])
    t_out[2] = np.nan
    am = average_method(t_in, t_out, q, 2)  # day 1: one pair, day 2: one pair
    np.testing.assert_allclose(am.r, [2.0, 2.0])


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="one length"):
        average_method(np.zeros(4), np.zeros(3), np.zeros(4), 1)
    with pytest.raises(ValueError, match="at least 1"):
        average_method(np.zeros(4), np.zeros(4), np.zeros(4), 0)
