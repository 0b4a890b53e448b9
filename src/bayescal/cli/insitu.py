"""The ISO 9869-1 average method on a wall study's training days (a line of ``bayescal show``).

For a built-in wall with the measured surface temperatures imposed
(``[simulator] type = "wall"``, ``boundary = "surface"``), daily periods and a
measured ``heat_flux_in``, the in-situ U of :mod:`bayescal.iso9869` (R = sum of
T_si - T_se over the sum of the flux, U = 1 / (0.13 + R + 0.04)) on the
training days, joined in time order, and the day count at which the standard's
conditions (a) to (c) first hold: the standard's number beside the calibrated one.
"""

from __future__ import annotations

import numpy as np

from bayescal.config import Study, WallSimulator
from bayescal.data.measured import MeasuredData
from bayescal.iso9869 import R_SE, R_SI, average_method


def iso9869_line(study: Study, measured: MeasuredData) -> str | None:
    """One line on the ISO 9869-1 average method, or None where it does not apply."""
    section = study.simulator
    if not isinstance(section, WallSimulator) or section.boundary != "surface":
        return None
    series = measured.forcing.series
    flux = measured.outputs.get("heat_flux_in", measured.held_out.get("heat_flux_in"))
    per_day = round(86400.0 / measured.step)
    layout = measured.layout
    if flux is None or not {"temp_surf_in", "temp_surf_out"} <= set(series):
        return None
    if layout.period != per_day or layout.m_star < 1:
        return None

    def days(values: np.ndarray) -> np.ndarray:
        return layout.cut(np.asarray(values, dtype=float)).T.ravel()

    am = average_method(
        days(series["temp_surf_in"]), days(series["temp_surf_out"]), -days(flux), per_day
    )
    head = f"ISO 9869-1 average method on the {layout.m_star} training days: "
    if not np.isfinite(am.u[-1]):
        return head + "no positive R (the heat flowed out of the wall on balance), no U"
    first = am.first_converged
    met = (
        f"its conditions (a)-(c) first met after {first} days"
        if first is not None
        else "its conditions (a)-(c) never met"
    )
    return (
        f"{head}U = {am.u[-1]:.3f} W/(m²·K) (R = {am.r[-1]:.2f} m²·K/W surface to surface, "
        f"R_si + R_se = {R_SI} + {R_SE}); {met}, at the end "
        f"{'met' if am.converged[-1] else 'not met'}"
    )
