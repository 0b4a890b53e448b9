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
        pass
    if name.upper() in _ABBREVIATIONS:
        meanings = "; ".join(
            f"{what} is {zone!r} or 'UTC{offset}'"
            if season == _NO
            else f"{what} is {zone!r} ({season}) or 'UTC{offset}' (all year)"
            for what, zone, season, offset in _ABBREVIATIONS[name.upper()]
        )
        raise ValueError(
            f"unknown time zone {text!r}: an abbreviation names no single zone; {meanings}"
        )
    raise ValueError(
        f"unknown time zone {text!r}: expected an IANA name such as 'Europe/Brussels' "
        f"or a fixed offset such as 'UTC+01:00'{_zone_hint(name)}"
    )


def _zone_hint(name: str) -> str:
    """``"; did you mean 'America/Chicago'?"``: regional IANA names close to ``name``, or
    those whose city is ``name`` (legacy aliases such as 'UCT' are not suggested)."""
    regional = sorted(z for z in available_timezones() if "/" in z and not z.startswith("Etc/"))
    cities = {z.rsplit("/", 1)[-1].lower(): z for z in regional}
    key = name.replace(" ", "_").lower()
    close = [cities[key]] if key in cities else []
    close += difflib.get_close_matches(name, regional, n=3)
    close = list(dict.fromkeys(close))[:3]
    return f"; did you mean {', '.join(map(repr, close))}?" if close else ""


_S, _D, _NO = "with its daylight saving", "daylight time in summer", "no daylight saving"
_ABBREVIATIONS: dict[str, tuple[tuple[str, str, str, str], ...]] = {
    # abbreviation -> (what it usually means, IANA zone, note, offset of the abbreviation)
    "CST": (
        ("US Central Standard Time", "America/Chicago", _D, "-06:00"),
        ("China Standard Time", "Asia/Shanghai", _NO, "+08:00"),
    ),
    "CDT": (("US Central Daylight Time", "America/Chicago", _S, "-05:00"),),
    "EDT": (("US Eastern Daylight Time", "America/New_York", _S, "-04:00"),),
    "MDT": (("US Mountain Daylight Time", "America/Denver", _S, "-06:00"),),
    "PST": (("US Pacific Standard Time", "America/Los_Angeles", _D, "-08:00"),),
    "PDT": (("US Pacific Daylight Time", "America/Los_Angeles", _S, "-07:00"),),
    "AKST": (("Alaska Standard Time", "America/Anchorage", _D, "-09:00"),),
    "CEST": (("Central European Summer Time", "Europe/Brussels", _S, "+02:00"),),
    "BST": (("British Summer Time", "Europe/London", _S, "+01:00"),),
    "WEST": (("Western European Summer Time", "Europe/Lisbon", _S, "+01:00"),),
    "EEST": (("Eastern European Summer Time", "Europe/Athens", _S, "+03:00"),),
    "IST": (
        ("India Standard Time", "Asia/Kolkata", _NO, "+05:30"),
        ("Irish Standard Time", "Europe/Dublin", _S, "+01:00"),
    ),
    "JST": (("Japan Standard Time", "Asia/Tokyo", _NO, "+09:00"),),
    "KST": (("Korea Standard Time", "Asia/Seoul", _NO, "+09:00"),),
    "AEST": (("Australian Eastern Standard Time", "Australia/Sydney", _D, "+10:00"),),
    "AEDT": (("Australian Eastern Daylight Time", "Australia/Sydney", _S, "+11:00"),),
    "AWST": (("Australian Western Standard Time", "Australia/Perth", _NO, "+08:00"),),
    "NZST": (("New Zealand Standard Time", "Pacific/Auckland", _D, "+12:00"),),
    "MSK": (("Moscow Time", "Europe/Moscow", _NO, "+03:00"),),
    "SGT": (("Singapore Time", "Asia/Singapore", _NO, "+08:00"),),
    "BRT": (("Brasília Time", "America/Sao_Paulo", _NO, "-03:00"),),
}
"""Common zone abbreviations that are not IANA names (EST, MST, HST and CET are, as
fixed zones), with the zones they usually mean."""
