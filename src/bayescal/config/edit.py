"""Edits of a study file that keep its comments and layout: the screening flags.

``bayescal screen --apply`` sets ``screen = false`` on the parameters it
proposes and ``screen = true`` on the others. The file is edited line by
line (TOML libraries that write lose the comments a study file lives by):
inside each ``[parameters.<name>]`` table an existing ``screen = ...`` line
is rewritten, or one is added under the table's header. The result is
validated before it replaces the file (atomically); the previous file is
kept beside it as ``study.toml.bak``.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping
from pathlib import Path

from bayescal.atomic import atomic_write_text
from bayescal.errors import ConfigError

__all__ = ["BACKUP_SUFFIX", "set_screen_flags"]

BACKUP_SUFFIX = ".bak"
_HEADER = re.compile(r"^\s*\[\s*parameters\s*\.\s*(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*\]\s*(#.*)?$")
_ANY_HEADER = re.compile(r"^\s*\[")
_SCREEN = re.compile(r"^(?P<indent>\s*)screen\s*=\s*(true|false)\s*(?P<comment>#.*)?$")


def _edited(text: str, flags: Mapping[str, bool]) -> str:
    lines = text.splitlines(keepends=True)
    out: list[str] = []
    current: str | None = None
    done: set[str] = set()

    def close_table() -> None:
        if current is not None and current in flags and current not in done:
            at = len(out)
            while at > 0 and not out[at - 1].strip():  # before the blank lines ending the table
                at -= 1
            out.insert(at, f"screen = {str(flags[current]).lower()}\n")
            done.add(current)

    for line in lines:
        header = _HEADER.match(line)
        if header or _ANY_HEADER.match(line):
            close_table()
            current = header["name"] if header else None
            out.append(line)
            continue
        match = _SCREEN.match(line)
        if match and current is not None and current in flags and current not in done:
            comment = f"  {match['comment']}" if match["comment"] else ""
            out.append(f"{match['indent']}screen = {str(flags[current]).lower()}{comment}\n")
            done.add(current)
            continue
        out.append(line)
    if out and not out[-1].endswith("\n"):
        out[-1] += "\n"
    close_table()
    return "".join(out)


def set_screen_flags(path: Path, flags: Mapping[str, bool]) -> list[str]:
    """Set ``screen`` of the named parameters in a study file, keeping everything else.

    Parameters
    ----------
    path
        The study file.
    flags
        Parameter name -> ``screen`` value (``False``: calibrate it).

    Returns
    -------
    list of str
        The parameters whose flag changed.

    Raises
    ------
    ConfigError
        If a name has no ``[parameters.<name>]`` table written as such (an
        inline or dotted definition cannot be edited), or the edited file
        does not read back with the requested flags.
    """
    text = path.read_text(encoding="utf-8")
    before = tomllib.loads(text).get("parameters", {})
    headers = {m["name"] for line in text.splitlines() if (m := _HEADER.match(line))}
    missing = sorted(set(flags) - headers)
    if missing:
        raise ConfigError(
            f"no [parameters.<name>] table for {missing} in {path.name}",
            hint="write each parameter as its own [parameters.<name>] table to let "
            "bayescal screen --apply edit it",
            source=str(path),
        )
    edited = _edited(text, flags)
    after = tomllib.loads(edited).get("parameters", {})
    wrong = [n for n, flag in flags.items() if bool(after[n].get("screen", False)) != flag]
    if wrong:  # pragma: no cover - a layout the line editor did not foresee
        raise ConfigError(f"could not set screen on {wrong}; edit {path.name} by hand")
    changed = [n for n, flag in flags.items() if bool(before[n].get("screen", False)) != flag]
    if changed:
        try:
            atomic_write_text(path.with_name(path.name + BACKUP_SUFFIX), text)
            atomic_write_text(path, edited)
        except OSError as exc:  # a read-only study folder, a full disk
            raise ConfigError(
                f"cannot write the screen flags into {path} ({exc.strerror or exc})",
                hint="make the study folder writable and run bayescal screen --apply again "
                "(the screening's results are kept), or set the flags by hand",
                source=str(path),
            ) from exc
    return changed
