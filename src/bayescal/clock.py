"""Durations and time zones as a study writes them.

A study file gives durations with a unit (``"30min"``, ``"1h"``, ``"1D"``)
and time zones as IANA names (``"Europe/Brussels"``) or fixed offsets
(``"UTC+01:00"``). These functions read and write them; the configuration
checks its values with them and the data layer aligns records with them.
"""

from __future__ import annotations

import difflib
import re
from datetime import UTC, datetime, timedelta, timezone, tzinfo
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError, available_timezones

import pandas as pd

from bayescal.errors import ConfigError

__all__ = [
    "format_duration",
    "local_time_problem",
    "local_to_utc",
    "offset_text",
    "parse_duration",
    "parse_time_zone",
]

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


def offset_text(offset: timedelta) -> str:
    """A UTC offset as a study writes it: ``"UTC+01:00"``, ``"UTC-06:00"``."""
    minutes = round(offset.total_seconds() / 60)
    sign = "-" if minutes < 0 else "+"
    hours, rest = divmod(abs(minutes), 60)
    return f"UTC{sign}{hours:02d}:{rest:02d}"


def local_time_problem(value: datetime | pd.Timestamp, zone: tzinfo) -> tuple[str, str] | None:
    """Why a local time of ``zone`` names no single instant, and how to fix it; ``None``
    where it does (or carries its own UTC offset).

    A daylight-saving zone repeats an hour when its clocks go back (``2013-10-27T02:30``
    in Europe/Berlin occurs twice: the message gives both UTC instants) and skips one
    when they go forward (``2013-03-31T02:30`` does not exist there).

    Returns
    -------
    tuple of str or None
        ``(message, hint)``; the message starts with the time as
        ``2013-10-27T02:30:00``.
    """
    ts = pd.Timestamp(value)
    if pd.isna(ts) or ts.tz is not None:  # no time, or one with its own offset
        return None
    if not pd.isna(ts.tz_localize(zone, ambiguous="NaT", nonexistent="NaT")):
        return None
    text, day = f"{ts:%Y-%m-%dT%H:%M:%S}", f"{ts:%Y-%m-%d}"
    if pd.isna(ts.tz_localize(zone, ambiguous="NaT", nonexistent="shift_forward")):
        first, second = (ts.tz_localize(zone, ambiguous=dst) for dst in (True, False))
        offsets = [offset_text(t.utcoffset() or timedelta()) for t in (first, second)]
        instants = " or ".join(
            f"{t.tz_convert('UTC'):%Y-%m-%d %H:%M} UTC ({o})"
            for t, o in zip((first, second), offsets, strict=True)
        )
        span, noun = _span((first.utcoffset() or timedelta()) - (second.utcoffset() or timedelta()))
        return (
            f"{text} occurs twice in time zone {zone}, whose clocks go back {span} on {day}: "
            f"it is {instants}",
            f"write the one meant with its offset, '{text}{offsets[0][3:]}' or "
            f"'{text}{offsets[1][3:]}', or give a time outside the repeated {noun}",
        )
    start, end = _gap(ts, zone)
    skipped = (end.utcoffset() or timedelta()) - (start.utcoffset() or timedelta())
    standard = offset_text(start.utcoffset() or timedelta())
    span, noun = _span(skipped)
    return (
        f"{text} does not exist in time zone {zone}, whose clocks skip {span} "
        f"from {end.tz_localize(None) - skipped:%H:%M} to {end:%H:%M} on {day}",
        f"give a time outside the skipped {noun} (e.g. "
        f"'{end:%Y-%m-%dT%H:%M:%S}', {end.tz_convert('UTC'):%H:%M} UTC), or, if the "
        "data's clock keeps standard time all year, set data.time_zone to its fixed offset "
        f"'{standard}'",
    )


def _gap(ts: pd.Timestamp, zone: tzinfo) -> tuple[pd.Timestamp, pd.Timestamp]:
    """The last instant before and the first after the clock change that skips the local
    time ``ts`` (aware, in ``zone``), found by bisection in UTC to the second: pandas'
    ``nonexistent`` shifts assume a skip of one hour (Antarctica/Troll skips two)."""
    wall = ts.to_pydatetime()
    before = wall.replace(tzinfo=zone, fold=0).utcoffset() or timedelta()
    after = wall.replace(tzinfo=zone, fold=1).utcoffset() or timedelta()
    low, high = sorted((ts - after, ts - before))  # the change lies between (naive UTC)
    low, high = low - timedelta(days=1), high + timedelta(days=1)

    def offset(utc: pd.Timestamp) -> timedelta:
        return utc.tz_localize("UTC").tz_convert(zone).utcoffset() or timedelta()

    first = offset(low)
    while high - low > timedelta(seconds=1):
        middle = low + (high - low) / 2
        low, high = (middle, high) if offset(middle) == first else (low, middle)
    end = high.tz_localize("UTC").tz_convert(zone)
    return end - timedelta(seconds=1), end


def _span(change: timedelta) -> tuple[str, str]:
    """``("an hour", "hour")``, ``("by 30 minutes", "30 minutes")``: how far a
    daylight-saving change moves the clocks, and the stretch it repeats or skips."""
    minutes = round(change.total_seconds() / 60)
    if minutes == 60:
        return "an hour", "hour"
    if minutes % 60 == 0:
        return f"by {minutes // 60} hours", f"{minutes // 60} hours"
    return f"by {minutes} minutes", f"{minutes} minutes"


def local_to_utc(value: datetime | pd.Timestamp, zone: tzinfo, what: str) -> pd.Timestamp:
    """``value`` in UTC; a naive one is a local time of ``zone``.

    Parameters
    ----------
    value
        The instant.
    zone
        Zone of a naive ``value``.
    what
        The key or option that gave it (``"data.start"``, ``"--from"``), for messages.

    Raises
    ------
    ConfigError
        A local time that a daylight-saving change repeats or skips
        (:func:`local_time_problem`).
    """
    ts = pd.Timestamp(value)
    if ts.tz is not None:
        return ts.tz_convert("UTC")
    problem = local_time_problem(ts, zone)
    if problem is not None:
        raise ConfigError(f"{what}: {problem[0]}", hint=problem[1])
    return ts.tz_localize(zone).tz_convert("UTC")


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
