"""Cache keys of simulator runs: fingerprints of the simulator and the boundary conditions.

A run is identified by :func:`run_key`, the SHA-256 of the simulator's
configuration (:func:`simulator_fingerprint`), the boundary conditions
(:func:`forcing_fingerprint`) and the run's parameter values. The keys are
the same in every process and every Python session, so a run cached once is
found again.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.errors import SimulatorError
from bayescal.simulators.base import Forcing

__all__ = [
    "FINGERPRINT_NAMES",
    "RUN_FORMAT",
    "forcing_fingerprint",
    "qualname",
    "run_key",
    "simulator_fingerprint",
]

RUN_FORMAT = "bayescal-run/1"


FINGERPRINT_NAMES = {
    f"bayescal.simulators.wrappers.{name}": f"bayescal.simulators.factory.{name}"
    for name in ("TargetedSimulator", "SensorModel")
}
"""Classes moved since runs were cached -> the name under which they enter fingerprints.

A fingerprint holds the ``module.Class`` of the objects it describes; a class
that moves keeps its old name here, so that runs cached before the move are
found again (issue 14 moved the two wrappers out of ``simulators.factory``)."""


def qualname(obj: Any) -> str:
    """``module.Class`` of an object (or of a class)."""
    kind = obj if isinstance(obj, type) else type(obj)
    return f"{kind.__module__}.{kind.__qualname__}"


def _stable_name(name: str) -> str:
    """The name a ``module.Class`` takes in fingerprints (see :data:`FINGERPRINT_NAMES`)."""
    return FINGERPRINT_NAMES.get(name, name)


def _canonical(obj: Any, seen: frozenset[int] = frozenset()) -> Any:
    """A JSON-able description of ``obj`` that is the same in every process."""
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    if isinstance(obj, np.ndarray):
        if obj.dtype.hasobject:
            return {"ndarray": "object", "items": _canonical(obj.tolist(), seen)}
        data = np.ascontiguousarray(obj)
        digest = hashlib.sha256(data.tobytes()).hexdigest()
        return {"ndarray": data.dtype.str, "shape": list(data.shape), "sha256": digest}
    if isinstance(obj, np.generic):
        return {"numpy": obj.dtype.str, "value": _canonical(obj.item(), seen)}
    if isinstance(obj, bytes):
        return {"bytes": hashlib.sha256(obj).hexdigest()}
    if isinstance(obj, Path | os.PathLike):
        return {"path": os.fspath(obj)}
    if isinstance(obj, enum.Enum):
        return {"enum": _stable_name(qualname(obj)), "name": obj.name}
    if isinstance(obj, type) or (callable(obj) and hasattr(obj, "__qualname__")):
        return {"callable": _stable_name(f"{obj.__module__}.{obj.__qualname__}")}
    if id(obj) in seen:
        raise SimulatorError(f"cannot fingerprint {qualname(obj)}: it refers to itself")
    seen = seen | {id(obj)}
    if isinstance(obj, Mapping):
        items = [[_canonical(k, seen), _canonical(v, seen)] for k, v in obj.items()]
        return {"mapping": sorted(items, key=lambda kv: json.dumps(kv[0], sort_keys=True))}
    if isinstance(obj, list | tuple):
        return {type(obj).__name__: [_canonical(v, seen) for v in obj]}
    if isinstance(obj, set | frozenset):
        items = [_canonical(v, seen) for v in obj]
        return {"set": sorted(items, key=lambda v: json.dumps(v, sort_keys=True))}
    return _canonical_object(obj, seen)


def _canonical_object(obj: Any, seen: frozenset[int]) -> Any:
    method = getattr(obj, "fingerprint", None)
    if callable(method):
        text = method()
        if not isinstance(text, str):
            raise SimulatorError(
                f"{qualname(obj)}.fingerprint() must return a str, got {type(text).__name__}"
            )
        return {"class": _stable_name(qualname(obj)), "fingerprint": text}
    if dataclasses.is_dataclass(obj):
        state = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    elif hasattr(obj, "__dict__") or hasattr(obj, "__slots__"):
        state = dict(getattr(obj, "__dict__", {}))
        for slot in getattr(type(obj), "__slots__", ()):
            if hasattr(obj, slot):
                state[slot] = getattr(obj, slot)
    else:
        text = repr(obj)
        if " at 0x" in text:
            raise SimulatorError(
                f"cannot fingerprint {qualname(obj)}: its repr changes between processes",
                hint="give the simulator a fingerprint() method returning a str that "
                "identifies its configuration",
            )
        return {"class": _stable_name(qualname(obj)), "repr": text}
    return {"class": _stable_name(qualname(obj)), "state": _canonical(state, seen)}


def _sha256_json(obj: Any) -> str:
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def simulator_fingerprint(simulator: Any) -> str:
    """A stable hash of a simulator's configuration.

    Uses ``simulator.fingerprint()`` (a str) when the simulator has one;
    otherwise the class name and a canonical description of its state
    (dataclass fields, or the instance's attributes), in which arrays enter by
    the SHA-256 of their bytes. Pickle is not used, so the value does not
    depend on the Python or library versions. A simulator whose state holds
    objects without a stable description (their ``repr`` shows a memory
    address) must define ``fingerprint()``; so should one that fills caches
    in its attributes lazily.

    Parameters
    ----------
    simulator
        The simulator.

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    return _sha256_json(_canonical(simulator))


def forcing_fingerprint(forcing: Forcing) -> str:
    """A stable hash of the boundary conditions (clock, names and values).

    Parameters
    ----------
    forcing
        The boundary conditions.

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    digest = hashlib.sha256()
    start = np.asarray(forcing.start, dtype="datetime64[ns]")
    digest.update(f"step={float(forcing.step)!r};start={start}".encode())
    for name in sorted(forcing.series):
        values = np.ascontiguousarray(forcing[name], dtype="<f8")
        digest.update(f";{name}:{values.size}:".encode())
        digest.update(values.tobytes())
    return digest.hexdigest()


def run_key(simulator_fp: str, forcing_fp: str, parameters: Mapping[str, float]) -> str:
    """The cache key of one run.

    Parameters
    ----------
    simulator_fp
        :func:`simulator_fingerprint` of the simulator.
    forcing_fp
        :func:`forcing_fingerprint` of the boundary conditions.
    parameters
        Parameter name -> value, in physical units (exact float values matter).

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    values = {name: float(parameters[name]).hex() for name in sorted(parameters)}
    description = {
        "format": RUN_FORMAT,
        "simulator": simulator_fp,
        "forcing": forcing_fp,
        "parameters": values,
    }
    return _sha256_json(description)
