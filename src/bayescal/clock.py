"""Durations and time zones as a study writes them.

A study file gives durations with a unit (``"30min"``, ``"1h"``, ``"1D"``)
and time zones as IANA names (``"Europe/Brussels"``) or fixed offsets
(``"UTC+01:00"``). These functions read and write them; the configuration
checks its values with them and the data layer aligns records with them.
"""

from __future__ import annotations

import difflib
import re
from datetime import UTC, timedelta, timezone, tzinfo
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError, available_timezones

import pandas as pd

__all__ = ["format_duration", "parse_duration", "parse_time_zone"]

_OFFSET_RE = re.compile(r"^(?:UTC|GMT)?\s*([+-])\s*(\d{1,2})(?::?(\d{2}))?$", re.IGNORECASE)
_DURATION_RE = re.compile(r"[A-Za-z]")


def parse_duration(value: object) -> pd.Timedelta:
    """Read a duration such as ``"30min"``, ``"1h"``, ``"1D"`` or ``"10 minutes"``.

    Raises
    ------
    ValueError
        If ``value`` is not a string with a unit (a bare number is refused:
        its unit would be a guess).
    """
    if isinstance(value, pd.Timedelta):
        return value
    if isinstance(value, timedelta):
        return pd.Timedelta(value)
    if not isinstance(value, str) or not _DURATION_RE.search(value):
        raise ValueError(
            f"expected a duration with a unit such as '30min', '1h' or '1D', got {value!r}"
        )
    try:
        result = pd.Timedelta(value.strip())
    except (ValueError, TypeError):
        raise ValueError(
            f"cannot read {value!r} as a duration; write e.g. '30min', '1h', '1D'"
        ) from None
    if pd.isna(result):
        raise ValueError(f"expected a duration, got {value!r}")
    return result


def format_duration(value: pd.Timedelta | timedelta) -> str:
    """A short human-readable duration, e.g. ``"2 days 06:00:00"`` -> ``"2D 6h"``."""
    td = pd.Timedelta(value)
    seconds = round(td.total_seconds())
    if seconds == 0:
        return "0s"
    sign = "-" if seconds < 0 else ""
    seconds = abs(seconds)
    parts = []
    for unit, size in (("D", 86400), ("h", 3600), ("min", 60), ("s", 1)):
        count, seconds = divmod(seconds, size)
        if count:
            parts.append(f"{count}{unit}")
    return sign + " ".join(parts)


def parse_time_zone(text: str) -> tzinfo:
    """A time zone from an IANA name (``"Europe/Brussels"``) or a fixed offset.

    Fixed offsets are written ``"UTC+01:00"``, ``"+01:00"``, ``"UTC-5"``;
    ``"UTC"`` itself is accepted.

    Raises
    ------
    ValueError
        If the name is neither; the message suggests the nearest IANA names.
    """
    name = text.strip()
    if name.upper() in ("UTC", "GMT", "Z"):
        return UTC
    match = _OFFSET_RE.match(name)
    if match:
        sign, hours, minutes = match.groups()
        offset = timedelta(hours=int(hours), minutes=int(minutes or 0))
        if offset > timedelta(hours=14):
            raise ValueError(f"time zone offset {text!r} is beyond ±14 h")
        return timezone(-offset if sign == "-" else offset)
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError, OSError):  # OSError: "Europe" is a folder
        close = difflib.get_close_matches(name, sorted(available_timezones()), n=3)
        hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
        raise ValueError(
            f"unknown time zone {text!r}: expected an IANA name such as 'Europe/Brussels' "
            f"or a fixed offset such as 'UTC+01:00'{hint}"
        ) from None
