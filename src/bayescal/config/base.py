"""What every section of the study file shares: the frozen pydantic base, documented
fields, cross-field problems, name suggestions, paths, durations and instants.

Every field carries a description (its unit in brackets) and examples
(:func:`field_doc`); the study-file reference is generated from them.
"""

from __future__ import annotations

import difflib
import errno
import numbers
import os
import re
import stat
import types
from datetime import date, datetime, timedelta, tzinfo
from pathlib import Path
from typing import Annotated, Any, Union, get_args, get_origin

import pandas as pd
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationInfo, model_validator
from pydantic_core import PydanticCustomError

from bayescal.clock import local_time_problem, parse_duration

__all__ = [
    "IDENTIFIER",
    "STRICT_NUMBER",
    "Duration",
    "Instant",
    "Section",
    "field_doc",
    "local_time_problems",
    "raise_problems",
    "resolve_path",
    "suggestion",
]

STRICT_NUMBER = "strict_number"
"""The pydantic error type of a number-typed key given text, a bool or a fraction."""

IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
"""Names a study gives (parameters, layers): letters, digits and ``_``, no leading digit."""


class Section(BaseModel):
    """Base of every section: frozen, unknown keys are errors, numbers are strict.

    A field typed ``int`` takes whole numbers only (``30``, not ``30.0``, ``3e1``
    or ``"30"``), a field typed ``float`` takes numbers only (``0.12`` or ``1``,
    not ``"0.12"``), in lists and tables too; ``true`` is no number. pydantic
    alone would convert all of these silently.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    @model_validator(mode="before")
    @classmethod
    def _strict_numbers(cls, data: Any) -> Any:
        if isinstance(data, dict):
            problems = [
                (key, problem)
                for key, value in data.items()
                if key in cls.model_fields
                and (problem := _number_problem(value, cls.model_fields[key].annotation))
            ]
            if problems:  # config.messages puts each under its key path
                raise PydanticCustomError(STRICT_NUMBER, "{problems}", {"problems": problems})
        return data


def _bare(annotation: Any) -> Any:
    """``int | None`` -> ``int``; other unions are kept."""
    if get_origin(annotation) in (Union, types.UnionType):
        members = [m for m in get_args(annotation) if m is not type(None)]
        return members[0] if len(members) == 1 else annotation
    return annotation


def _number_problem(value: Any, annotation: Any) -> str | None:
    """What is wrong with ``value`` for a number-typed field, ``None`` if nothing is."""
    kind = _bare(annotation)
    origin = get_origin(kind)
    if origin in (list, tuple) and isinstance(value, list | tuple):
        args = [a for a in get_args(kind) if a is not Ellipsis]
        if len(args) == 1:
            return next((p for v in value if (p := _number_problem(v, args[0]))), None)
        return None
    if origin is dict and isinstance(value, dict):
        item = get_args(kind)[-1]
        return next((p for v in value.values() if (p := _number_problem(v, item))), None)
    if kind not in (int, float) or value is None:
        return None
    if isinstance(value, str):
        return f"expected a number, got the text {value!r}; write the number without quotes"
    if isinstance(value, bool):
        return f"expected a number, got {str(value).lower()}"
    if kind is int and isinstance(value, numbers.Real) and not isinstance(value, numbers.Integral):
        return f"expected a whole number (no decimal point or exponent), got {value!r}"
    return None


def field_doc(description: str, *examples: Any, **constraints: Any) -> Any:
    """A documented field: description (unit in brackets), examples, constraints."""
    return Field(description=description, examples=list(examples), **constraints)


def raise_problems(messages: list[str]) -> None:
    """Raise the collected cross-field problems (each message starts with its key path)."""
    if messages:
        raise PydanticCustomError("cross_check", "{text}", {"text": "; ".join(messages)})


def local_time_problems(times: dict[str, datetime | None], zone: tzinfo) -> list[str]:
    """Problems of local times (key path -> value) that a daylight-saving change of
    ``zone`` repeats or skips (:func:`bayescal.clock.local_time_problem`)."""
    found = {key: local_time_problem(value, zone) for key, value in times.items() if value}
    return [f"{key}: {p[0]}; {p[1]}" for key, p in found.items() if p is not None]


def suggestion(name: str, valid: list[str] | tuple[str, ...]) -> str:
    """``"; did you mean 'x'?"`` for the closest valid name, else the list of valid names."""
    close = difflib.get_close_matches(name, list(valid), n=1)
    return f"; did you mean {close[0]!r}?" if close else f"; expected one of {', '.join(valid)}"


def path_problem(path: Path) -> str | None:
    """Why ``path`` cannot be read as a file, in a few words, or ``None`` if it can.

    ``"file not found"``, ``"not a file"``, ``"symbolic link loop (a.csv -> b.csv ->
    a.csv)"`` (a link that leads back to itself, here or in a folder on the path; the
    operating system gives up after a few dozen links), ``"broken symbolic link to
    'x.csv'"``, or the operating system's reason (permission denied).
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"symbolic link loop {_link_chain(path)}"
        if os.path.islink(path):
            return f"broken symbolic link to {os.readlink(path)!r}"
        if exc.errno == errno.ENOENT:
            return "file not found"
        return (exc.strerror or str(exc)).lower()
    return None if stat.S_ISREG(mode) else "not a file"


def _link_chain(path: Path, most: int = 6) -> str:
    """``(a.csv -> b.csv -> a.csv)``: the links from ``path`` until one repeats (or
    ``in a folder on the path`` where the loop is not in the last name)."""
    names, seen, here = [path.name], {os.path.abspath(path)}, str(path)
    while os.path.islink(here) and len(names) <= most:
        target = os.readlink(here)
        here = os.path.join(os.path.dirname(here), target)
        names.append(target)
        if os.path.abspath(here) in seen:
            return f"({' -> '.join(names)})"
        seen.add(os.path.abspath(here))
    return "in a folder on the path" if len(names) == 1 else f"({' -> '.join([*names, '...'])})"


def resolve_path(value: Path, info: ValidationInfo, what: str) -> Path:
    """An absolute path; relative ones start at the study folder and may not leave it."""
    if str(value) in ("", "."):
        raise ValueError(f"expected {what}, got {str(value)!r}")
    if value.is_absolute():
        return value
    root = Path(os.path.normpath(Path((info.context or {}).get("root", Path.cwd()))))
    resolved = Path(os.path.normpath(root / value))
    if not resolved.is_relative_to(root):
        raise ValueError(
            f"path {str(value)!r} leaves the study folder; give an absolute path or move "
            "it into the study folder"
        )
    return resolved


def _duration(value: object) -> timedelta:
    return parse_duration(value).to_pytimedelta()


def _instant(value: object) -> datetime:
    result = _parse_instant(value)
    if not 1678 <= result.year <= 2261:  # the range of nanosecond timestamps
        raise ValueError(f"expected a date-time between the years 1678 and 2261, got {value!r}")
    return result


def _parse_instant(value: object) -> datetime:
    if isinstance(value, datetime):
        return value
    if isinstance(value, date):
        return datetime(value.year, value.month, value.day)
    try:
        if not isinstance(value, str):
            raise TypeError
        return pd.Timestamp(value).to_pydatetime()
    except (ValueError, TypeError):
        raise ValueError(
            f"expected a date-time such as '2013-08-21T00:00:00', got {value!r}"
        ) from None


Duration = Annotated[timedelta, BeforeValidator(_duration)]
"""A duration written with a unit: ``"30min"``, ``"1h"``, ``"1D"``."""
Instant = Annotated[datetime, BeforeValidator(_instant)]
"""A date-time; naive values are local times of ``[data].time_zone``."""
