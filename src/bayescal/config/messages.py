"""Validation errors of the study file as one-line messages.

pydantic reports each problem with a location (``("simulator", "wall",
"layers", 0, "name")``), a type and a message. :func:`format_errors` turns
each into ``key.path: what was wrong, got <value>``: union branch labels that
pydantic inserts are dropped from the key path, an unknown key gets the
closest valid key, and cross-field problems (raised with
:func:`bayescal.config.base.raise_problems`) keep their own key paths.
"""

from __future__ import annotations

import difflib
import types
from typing import Any, Literal, Union, get_args, get_origin

from pydantic import BaseModel, ValidationError

from bayescal.config.base import STRICT_NUMBER

__all__ = ["format_errors"]

_TYPE_LABELS = frozenset({"str", "int", "float", "bool", "timedelta", "datetime", "none"})


def _members(node: Any) -> list[Any]:
    if get_origin(node) in (Union, types.UnionType):
        return [m for m in get_args(node) if m is not type(None)]
    return [node]


def _tag_of(member: Any) -> tuple[Any, ...]:
    """Literal values of a union member's discriminator field (``("wall",)``)."""
    if isinstance(member, type) and issubclass(member, BaseModel):
        for field in member.model_fields.values():
            if get_origin(field.annotation) is Literal:
                return get_args(field.annotation)
    return ()


def _walk(loc: tuple[int | str, ...], model: type[BaseModel]) -> tuple[list[int | str], Any]:
    """The key path shown for an error location, and the type found there.

    Union branch labels that pydantic inserts (``"wall"``, ``"int"``) are skipped.
    """
    node: Any = model
    shown: list[int | str] = []
    for part in loc:
        members = _members(node)
        if len(members) > 1:
            tagged = [m for m in members if part in _tag_of(m)]
            if tagged or (isinstance(part, str) and (part in _TYPE_LABELS or "[" in part)):
                node = tagged[0] if tagged else None
                continue
        node = members[0]
        shown.append(part)
        if isinstance(node, type) and issubclass(node, BaseModel):
            field = node.model_fields.get(str(part))
            node = field.annotation if field is not None else None
        elif get_origin(node) in (dict, list):
            node = get_args(node)[-1]
        else:
            node = None
    return shown, node


def _join(parts: list[int | str]) -> str:
    text = ""
    for part in parts:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _unknown_key(loc: tuple[int | str, ...], model: type[BaseModel]) -> str:
    shown, parent = _walk(loc[:-1], model)
    full = _join([*shown, loc[-1]])
    if not (isinstance(parent, type) and issubclass(parent, BaseModel)):
        return f"unknown key {full!r}"
    valid = list(parent.model_fields)
    close = difflib.get_close_matches(str(loc[-1]), valid, n=1)
    if close:
        return f"unknown key {full!r}; did you mean {_join([*shown, close[0]])!r}?"
    return f"unknown key {full!r}; valid keys here: {', '.join(valid)}"


def format_errors(exc: ValidationError, model: type[BaseModel]) -> list[str]:
    """One message per pydantic error: key path, value received, what was expected.

    Parameters
    ----------
    exc
        The error of validating ``model`` (for a study file: :class:`bayescal.config.Study`).
    model
        The model validated, whose fields name the key paths.
    """
    messages: list[str] = []
    for err in exc.errors(include_url=False):
        loc, kind, ctx = tuple(err["loc"]), err["type"], err.get("ctx") or {}
        shown, node = _walk(loc, model)
        path = _join(shown)
        if kind == "cross_check":  # messages carry their own full key paths
            message = str(ctx["text"])
        elif kind == STRICT_NUMBER:  # raised by the section: one problem per key
            message = "; ".join(f"{_join([*shown, k])}: {text}" for k, text in ctx["problems"])
        elif kind == "extra_forbidden":
            message = _unknown_key(loc, model)
        elif kind == "missing":
            message = f"{path}: missing required key"
        elif kind in ("union_tag_not_found", "union_tag_invalid"):
            key = str(ctx.get("discriminator", "")).strip("'")
            tags = ", ".join(repr(t) for m in _members(node) for t in _tag_of(m))
            got = f"unknown value {ctx['tag']!r}" if "tag" in ctx else "missing"
            message = f"{_join([*shown, key])}: {got}; expected one of {tags}"
        else:
            text = str(err["msg"]).removeprefix("Value error, ")
            text = text[:1].lower() + text[1:]
            if kind != "value_error" and not isinstance(err.get("input"), dict | list):
                text += f", got {err.get('input')!r}"
            message = f"{path}: {text}" if path else text
        if message not in messages:
            messages.append(message)
    return messages
