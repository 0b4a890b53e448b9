"""Small simulators for the runner tests (module level, so worker processes can import them).

All share the analytic response of :class:`Analytic`; the others add a
failure mode that switches on when parameter ``a`` reaches ``threshold``.
"""

from __future__ import annotations

import hashlib
import os
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from bayescal.errors import SimulatorError
from bayescal.simulators.base import Forcing, check_parameters

PERIOD = 86_400.0  # period of the sine output [s]


def reference(a: float, b: float, forcing: Forcing) -> dict[str, np.ndarray]:
    """The analytic outputs, written independently of the simulators below."""
    t = np.arange(forcing.n) * forcing.step
    return {
        "y": a * forcing["temp_air_out"] + b,
        "z": b * np.sin(2 * np.pi * t / PERIOD) + a * a,
    }


@dataclass(frozen=True)
class Analytic:
    """``y = a * temp_air_out + b``, ``z = b sin(2 pi t / 1 day) + a^2``."""

    gain: float = 1.0
    parameter_names: ClassVar[tuple[str, ...]] = ("a", "b")
    input_names: ClassVar[tuple[str, ...]] = ("temp_air_out",)
    output_names: ClassVar[tuple[str, ...]] = ("y", "z")

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        check_parameters(parameters, self.parameter_names, "Analytic")
        a, b = parameters["a"], parameters["b"]
        steps = np.arange(forcing.n, dtype=float)
        phase = 2 * np.pi * steps * forcing.step / PERIOD
        return {
            "y": self.gain * (a * forcing["temp_air_out"] + b),
            "z": b * np.sin(phase) + a**2,
        }


@dataclass(frozen=True)
class Failing(Analytic):
    """Raises :class:`SimulatorError` when ``a >= threshold``."""

    threshold: float = 0.9

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        if parameters["a"] >= self.threshold:
            raise SimulatorError(f"diverged at a={parameters['a']:.3f}")
        return super().simulate(parameters, forcing)


class ExternalFailure(SimulatorError):
    """Like an external program's failure: carries an exit code and stderr."""

    def __init__(self, message: str, *, exit_code: int, stderr: str):
        self.exit_code = exit_code
        self.stderr = stderr
        super().__init__(message)


@dataclass(frozen=True)
class FailingExternal(Analytic):
    """Raises :class:`ExternalFailure` (exit code 7) when ``a >= threshold``."""

    threshold: float = 0.9

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        if parameters["a"] >= self.threshold:
            raise ExternalFailure("solver exited", exit_code=7, stderr="** Severe: no convergence")
        return super().simulate(parameters, forcing)


@dataclass(frozen=True)
class Hanging(Analytic):
    """Sleeps (practically) forever when ``a >= threshold``."""

    threshold: float = 0.9

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        if parameters["a"] >= self.threshold:
            time.sleep(3600)
        return super().simulate(parameters, forcing)


@dataclass(frozen=True)
class Crashing(Analytic):
    """Kills its own process (exit status 3) when ``a >= threshold``."""

    threshold: float = 0.9

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        if parameters["a"] >= self.threshold:
            os._exit(3)
        return super().simulate(parameters, forcing)


@dataclass(frozen=True)
class Slow(Analytic):
    """Sleeps ``delay`` seconds, then returns the analytic response."""

    delay: float = 0.3

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        time.sleep(self.delay)
        return super().simulate(parameters, forcing)


@dataclass(frozen=True)
class Flaky(Analytic):
    """Fails the first attempt of every parameter set (remembered in ``marker_dir``)."""

    marker_dir: str = "."

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        text = repr(sorted(parameters.items())).encode()
        marker = Path(self.marker_dir) / hashlib.sha256(text).hexdigest()
        if not marker.exists():
            marker.touch()
            raise SimulatorError("first attempt fails")
        return super().simulate(parameters, forcing)


@dataclass(frozen=True)
class Chatty(Analytic):
    """Prints to standard output while it runs (must not disturb the runner)."""

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        print("solver says hello\n" * 50, flush=True)
        return super().simulate(parameters, forcing)


@dataclass(frozen=True)
class BadShape(Analytic):
    """Returns one sample too few for ``y`` when ``a >= threshold``."""

    threshold: float = 0.9

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        outputs = super().simulate(parameters, forcing)
        if parameters["a"] >= self.threshold:
            outputs["y"] = outputs["y"][:-1]
        return outputs


class WithFingerprint:
    """A plain class that names its configuration itself."""

    parameter_names = ("a", "b")
    input_names = ("temp_air_out",)
    output_names = ("y", "z")

    def __init__(self, version: str):
        self.version = version
        self._cache: dict[str, float] = {}

    def fingerprint(self) -> str:
        return f"with-fingerprint {self.version}"

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        self._cache["last"] = parameters["a"]
        return Analytic().simulate(parameters, forcing)


class Opaque:
    """Holds a lock, whose repr shows a memory address."""

    parameter_names = ("a", "b")
    input_names = ("temp_air_out",)
    output_names = ("y", "z")

    def __init__(self) -> None:
        self.lock = threading.Lock()


@dataclass(frozen=True)
class SlowToLoad(Analytic):
    """Takes ``load_delay`` seconds to unpickle, like a simulator with heavy imports."""

    load_delay: float = 1.5

    def __setstate__(self, state: dict[str, float]) -> None:
        time.sleep(state["load_delay"])
        self.__dict__.update(state)


@dataclass(frozen=True)
class Faulty(Analytic):
    """Fails for ``b`` below ``fail`` and hangs for ``b`` in [``fail``, ``hang``)."""

    fail: float = 0.10
    hang: float = 0.12

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        b = parameters["b"]
        if b < self.fail:
            raise SimulatorError(f"diverged at b={b:.4f}")
        if b < self.hang:
            time.sleep(3600)
        return super().simulate(parameters, forcing)


@dataclass(frozen=True)
class Logged(Analytic):
    """Sleeps ``delay`` seconds; appends ``start``/``done`` lines to ``log`` (a file).

    Each line is ``<event> <a> <b> <ppid>``: the parameters name the run, the
    parent process (a runner worker's sandbox runs in a child of the Dask
    worker) names the worker that ran it.
    """

    log: str = "runs.log"
    delay: float = 1.0

    def _write(self, event: str, parameters: Mapping[str, float]) -> None:
        line = f"{event} {parameters['a']!r} {parameters['b']!r} {os.getppid()}\n"
        with open(self.log, "a", encoding="utf-8") as stream:  # O_APPEND: whole lines
            stream.write(line)

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        self._write("start", parameters)
        time.sleep(self.delay)
        out = super().simulate(parameters, forcing)
        self._write("done", parameters)
        return out
