"""The in-situ thermal resistance of a wall by the average method of ISO 9869-1:2014.

A heat-flux plate and two surface temperatures measured for some days give the
wall's thermal resistance, surface to surface, by the *average method*
(ISO 9869-1:2014, section 7.2)::

    R = sum_j (T_si,j - T_se,j) / sum_j q_j        [m²·K/W]

over every sample ``j`` measured so far, and its thermal transmittance::

    U = 1 / (R_si + R + R_se)                       [W/(m²·K)]

with the conventional surface resistances of EN ISO 6946 for horizontal heat
flow, ``R_si = 0.13`` and ``R_se = 0.04`` m²·K/W (:data:`R_SI`, :data:`R_SE`).
``q`` is the heat flow density through the wall, positive from the inside face to
the outside face (bayescal's ``heat_flux_in`` is positive from the wall into the
room: ``q = -heat_flux_in``).

:func:`average_method` evaluates R and U after each whole day ``D = 1, 2, ...``
(cumulative over the first ``D`` days: the record is cut into 24-hour blocks
from its first sample; a trailing part day is not used) and, for each ``D``, the
standard's conditions for ending the test on a heavy element (areal heat
capacity above 20 kJ/(m²·K)), as implemented here:

(a) **duration**: ``D >= 3``, i.e. at least 72 h of whole days;
(b) **24-hour stability**: ``|R(D) - R(D-1)| <= 0.05 |R(D-1)|`` (the R at the
    end within ±5 % of the R 24 hours before; false for ``D = 1``);
(c) **first against last**: with ``n = INT(2 D / 3)`` days, the R of the first
    ``n`` days and the R of the last ``n`` days (each a ratio of sums over its own
    days) satisfy ``|R_first - R_last| <= 0.05 |R_last|`` (false where ``n = 0``).

``converged`` is (a) and (b) and (c) and ``R(D) > 0``. Not implemented: the
standard's fourth condition for heavy elements (the change of the energy stored
in the element below 5 % of the heat that passed through it, which needs the
temperatures inside the wall), its night-time analysis for light elements, and
its corrections for storage effects (the "dynamic" method of its Annex B).
Samples where the temperature difference or the flux is not finite are left
out of every sum.

Numerical kernel: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Inside surface resistance, horizontal heat flow (EN ISO 6946). [m²·K/W]
R_SI = 0.13
#: Outside surface resistance (EN ISO 6946). [m²·K/W]
R_SE = 0.04
#: The standard's tolerance of conditions (b) and (c). [-]
TOLERANCE = 0.05
#: Condition (a): the shortest test. [days] (72 h)
MIN_DAYS = 3
#: Above this areal heat capacity an element is "heavy" (ISO 9869-1). [J/(m²·K)]
HEAVY = 20e3


@dataclass(frozen=True)
class AverageMethod:
    """R, U and the convergence conditions after each whole day.

    Every array has one entry per day count ``D = 1 .. days``.

    Attributes
    ----------
    days
        ``D``, the number of whole days used. [d]
    r
        Cumulative R over the first ``D`` days, surface to surface (NaN where the
        flux sums to zero). [m²·K/W]
    u
        ``1 / (r_si + R + r_se)`` (NaN where R is not positive). [W/(m²·K)]
    r_first, r_last
        R of the first and of the last ``INT(2 D / 3)`` days (NaN where none). [m²·K/W]
    duration, stable, first_last
        Conditions (a), (b) and (c).
    converged
        All three hold and R is positive.
    """

    days: np.ndarray
    r: np.ndarray
    u: np.ndarray
    r_first: np.ndarray
    r_last: np.ndarray
    duration: np.ndarray
    stable: np.ndarray
    first_last: np.ndarray
    converged: np.ndarray

    @property
    def first_converged(self) -> int | None:
        """The first day count at which the test may end (all conditions hold), or None."""
        hits = np.flatnonzero(self.converged)
        return int(self.days[hits[0]]) if hits.size else None

    def rows(self) -> list[dict[str, float | bool | int]]:
        """One dict per day count: ``days, R, U, a, b, c, converged``."""
        return [
            {
                "days": int(d),
                "R": float(r),
                "U": float(u),
                "a": bool(a),
                "b": bool(b),
                "c": bool(c),
                "converged": bool(ok),
            }
            for d, r, u, a, b, c, ok in zip(
                self.days,
                self.r,
                self.u,
                self.duration,
                self.stable,
                self.first_last,
                self.converged,
                strict=True,
            )
        ]


def u_value(r: np.ndarray | float, r_si: float = R_SI, r_se: float = R_SE) -> np.ndarray:
    """``1 / (r_si + r + r_se)``, NaN where ``r`` is not positive. [W/(m²·K)]"""
    r = np.asarray(r, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(r > 0.0, 1.0 / (r_si + r + r_se), np.nan)


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den != 0.0, num / np.where(den != 0.0, den, 1.0), np.nan)


def _within(value: np.ndarray, reference: np.ndarray, tolerance: float) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        ok = np.abs(value - reference) <= tolerance * np.abs(reference)
    return ok & np.isfinite(value) & np.isfinite(reference)


def daily_sums(
    temp_in: np.ndarray, temp_out: np.ndarray, flux_out: np.ndarray, samples_per_day: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per whole day, the sums of ``T_si - T_se`` and of ``q`` over the finite samples.

    Returns two arrays of shape ``(days,)``; a trailing part day is dropped.
    """
    if samples_per_day < 1:
        raise ValueError(f"samples_per_day must be at least 1, got {samples_per_day}")
    t_in, t_out, q = (np.asarray(a, dtype=float) for a in (temp_in, temp_out, flux_out))
    if not t_in.shape == t_out.shape == q.shape or t_in.ndim != 1:
        raise ValueError(
            f"temp_in, temp_out and flux_out must be 1-D of one length, got "
            f"{t_in.shape}, {t_out.shape}, {q.shape}"
        )
    days = t_in.size // samples_per_day
    dt = (t_in - t_out)[: days * samples_per_day].reshape(days, samples_per_day)
    q = q[: days * samples_per_day].reshape(days, samples_per_day)
    used = np.isfinite(dt) & np.isfinite(q)
    return np.where(used, dt, 0.0).sum(axis=1), np.where(used, q, 0.0).sum(axis=1)


def average_method(
    temp_in: np.ndarray,
    temp_out: np.ndarray,
    flux_out: np.ndarray,
    samples_per_day: int,
    *,
    r_si: float = R_SI,
    r_se: float = R_SE,
    tolerance: float = TOLERANCE,
) -> AverageMethod:
    """The ISO 9869-1 average method after each whole day of a record.

    Parameters
    ----------
    temp_in, temp_out
        Inside and outside surface temperatures, shape ``(n,)``. [°C]
    flux_out
        Heat flow density through the wall, positive from inside to outside,
        shape ``(n,)``. [W/m²]
    samples_per_day
        Samples in 24 hours (equally spaced record starting at a day's start).
    r_si, r_se
        Surface resistances added for U. [m²·K/W]
    tolerance
        Relative tolerance of conditions (b) and (c). [-]

    Returns
    -------
    AverageMethod
        One entry per whole day of the record (the module docstring states the
        conditions).
    """
    dt_day, q_day = daily_sums(temp_in, temp_out, flux_out, samples_per_day)
    n_days = dt_day.size
    days = np.arange(1, n_days + 1)
    cum_dt = np.concatenate([[0.0], np.cumsum(dt_day)])
    cum_q = np.concatenate([[0.0], np.cumsum(q_day)])
    r = _ratio(cum_dt[1:], cum_q[1:])
    previous = np.concatenate([[np.nan], r[:-1]])
    stable = _within(r, previous, tolerance)
    n = (2 * days) // 3
    r_first = _ratio(cum_dt[n], cum_q[n])
    r_last = _ratio(cum_dt[days] - cum_dt[days - n], cum_q[days] - cum_q[days - n])
    r_first = np.where(n > 0, r_first, np.nan)
    r_last = np.where(n > 0, r_last, np.nan)
    first_last = _within(r_first, r_last, tolerance)
    duration = days >= MIN_DAYS
    with np.errstate(invalid="ignore"):
        positive = r > 0.0
    return AverageMethod(
        days=days,
        r=r,
        u=u_value(r, r_si, r_se),
        r_first=r_first,
        r_last=r_last,
        duration=duration,
        stable=stable,
        first_last=first_last,
        converged=duration & stable & first_last & positive,
    )
