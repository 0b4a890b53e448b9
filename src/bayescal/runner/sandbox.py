"""Worker processes of the runner: run one simulation at a time, and can be killed.

Internal to :mod:`bayescal.runner`. A :class:`Sandbox` is a fresh Python
interpreter started with :mod:`subprocess` in its own process group (POSIX),
so that a run past its timeout is stopped together with any program it
started, and a crash of the simulator (``os._exit``, a segfault) ends only
the worker. Messages are length-prefixed pickles on the worker's stdin and
stdout; the worker's own stdout is redirected to stderr so that prints from
a simulator cannot corrupt them. A worker exits when its runner disappears
(end of file on stdin, or its parent process changes).

Timing: the clock of a run starts when it is sent to a worker that has
loaded the simulator, or when the worker reports it has (its first run), so
a simulator that is slow to import does not eat into ``timeout``; loading
itself must finish within :data:`STARTUP_LIMIT` when a timeout is set.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import pickle
import queue
import signal
import struct
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Mapping
from typing import IO, Any

import numpy as np

from bayescal.errors import SimulatorError
from bayescal.runner.keys import qualname
from bayescal.simulators.base import Forcing, Simulator

TEXT_TAIL = 10_000  # characters of stderr / traceback kept in a failure record
STARTUP_LIMIT = 120.0  # [s] a worker must load the simulator within this, if timeout is set


# ----------------------------------------------------------------- one simulation


def _tail(value: Any) -> str | None:
    if value is None:
        return None
    text = value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)
    return text[-TEXT_TAIL:]


def error_record(exc: BaseException) -> dict[str, Any]:
    """Plain (always picklable, JSON-able) description of an exception."""
    code = next(
        (getattr(exc, a) for a in ("exit_code", "returncode", "exitcode") if hasattr(exc, a)),
        None,
    )
    record: dict[str, Any] = {
        "type": qualname(exc),
        "message": str(exc) or repr(exc),
        "exit_code": code if isinstance(code, int) else None,
        "stderr": _tail(getattr(exc, "stderr", None)),
        "traceback": _tail("".join(traceback.format_exception(exc))),
    }
    for extra in ("command", "run_dir"):
        if getattr(exc, extra, None) is not None:
            value = getattr(exc, extra)
            record[extra] = list(value) if isinstance(value, tuple | list) else str(value)
    return record


def _check_outputs(raw: Any, names: tuple[str, ...], n: int) -> dict[str, np.ndarray]:
    if not isinstance(raw, Mapping):
        raise SimulatorError(f"simulate() must return a dict of series, got {type(raw).__name__}")
    missing = [name for name in names if name not in raw]
    if missing:
        raise SimulatorError(f"simulate() returned {sorted(raw)}, missing output(s) {missing}")
    outputs = {}
    for name in names:
        values = np.asarray(raw[name], dtype=float)
        if values.shape != (n,):
            raise SimulatorError(f"output {name!r} has shape {values.shape}, expected ({n},)")
        if not np.all(np.isfinite(values)):
            raise SimulatorError(f"output {name!r} contains NaN or infinite values")
        outputs[name] = values
    return outputs


def execute(simulator: Simulator, forcing: Forcing, parameters: dict[str, float]) -> dict:
    """Run once; never raises: returns ``{"ok", "seconds", "outputs" | "error"}``."""
    start = time.perf_counter()
    try:
        raw = simulator.simulate(parameters, forcing)
        outputs = _check_outputs(raw, tuple(simulator.output_names), forcing.n)
    except Exception as exc:  # any failure of user code is a failed run
        return {"ok": False, "seconds": time.perf_counter() - start, "error": error_record(exc)}
    return {"ok": True, "seconds": time.perf_counter() - start, "outputs": outputs}


def failure(kind: str, message: str, exit_code: int | None = None) -> dict:
    """The outcome of a run that the runner, not the simulator, declared failed."""
    error = {"type": kind, "message": message, "exit_code": exit_code, "stderr": None}
    return {"ok": False, "seconds": math.nan, "error": error}


# ---------------------------------------------------------------- worker process


def _write_message(stream: IO[bytes], obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack(">Q", len(data)) + data)
    stream.flush()


def _read_message(stream: IO[bytes]) -> tuple[bool, Any]:
    """``(True, message)``, or ``(False, None)`` at end of stream."""
    header = stream.read(8)
    if len(header) < 8:
        return False, None
    (size,) = struct.unpack(">Q", header)
    data = stream.read(size)
    if len(data) < size:
        return False, None
    return True, pickle.loads(data)


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(1.0)
    os._exit(1)  # the runner is gone: nobody will read our result


def sandbox_main() -> None:
    """Entry point of a worker subprocess (see :class:`Sandbox`)."""
    requests = sys.stdin.buffer
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # stray prints must not corrupt replies
    if os.name == "posix":
        threading.Thread(target=_watch_parent, args=(os.getppid(),), daemon=True).start()
    ok, sys_path = _read_message(requests)
    sys.path[:0] = [p for p in (sys_path or []) if p not in sys.path]
    ok, payload = _read_message(requests)
    if not ok:
        return
    try:
        simulator, forcing = pickle.loads(payload)
        broken = None
    except Exception as exc:  # reported with every run below
        broken = {"ok": False, "seconds": 0.0, "error": error_record(exc)}
    try:
        _write_message(replies, (None, None))  # ready: the run clocks start now
        while True:
            ok, request = _read_message(requests)
            if not ok or request is None:
                return
            token, parameters = request
            outcome = broken or execute(simulator, forcing, parameters)
            _write_message(replies, (token, outcome))
    except BrokenPipeError:
        os._exit(0)


_SANDBOX_CODE = "from bayescal.runner.sandbox import sandbox_main; sandbox_main()"
_STOP = object()


class Sandbox:
    """A worker subprocess that runs one simulation at a time.

    Messages are length-prefixed pickles on the child's stdin/stdout. A thread
    sends the (possibly large) simulator and boundary conditions while the
    child starts, and a reader thread posts ``(sid, (token, outcome))`` for
    each reply and ``(sid, None)`` when the child's stdout closes (it exited or
    was killed), so the caller never blocks on the pipes.

    Parameters
    ----------
    payload
        ``pickle_payload(simulator, forcing)``.
    events
        Queue that receives this sandbox's ``(sid, message)`` events; the
        process backend shares one among all its sandboxes.
    """

    _ids = itertools.count()

    def __init__(self, payload: bytes, events: queue.Queue[tuple[int, Any]]):
        self.sid = next(self._ids)
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _SANDBOX_CODE],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            start_new_session=os.name == "posix",
        )
        self.events = events
        self.born = time.monotonic()
        self.ready = False  # the child has unpickled the simulator
        self.started = math.nan  # when the outstanding run's clock started
        self._lock = threading.Lock()
        self._delivered = False  # the payload is written: requests go straight out
        self._held: list[Any] = []  # requests made before the payload was delivered
        threading.Thread(target=self._initialise, args=(payload,), daemon=True).start()
        threading.Thread(target=self._read_loop, daemon=True).start()

    def _initialise(self, payload: bytes) -> None:
        assert self.proc.stdin is not None
        with contextlib.suppress(OSError, ValueError):  # the child died: the reader reports it
            _write_message(self.proc.stdin, list(sys.path))
            _write_message(self.proc.stdin, payload)
        with self._lock:
            self._delivered = True
            for message in self._held:
                self._post(message)
            self._held.clear()

    def _post(self, message: Any) -> None:
        assert self.proc.stdin is not None
        with contextlib.suppress(OSError, ValueError):  # the child died: the reader reports it
            if message is _STOP:
                self.proc.stdin.close()
            else:
                _write_message(self.proc.stdin, message)

    def _deliver(self, message: Any) -> None:
        with self._lock:
            if self._delivered:
                self._post(message)
            else:
                self._held.append(message)

    def _read_loop(self) -> None:
        assert self.proc.stdout is not None
        while True:
            try:
                ok, message = _read_message(self.proc.stdout)
            except Exception:  # a reply cut short by a crash
                ok, message = False, None
            self.events.put((self.sid, message if ok else None))
            if not ok:
                self.proc.stdout.close()
                return

    def send(self, token: str, parameters: dict[str, float]) -> None:
        """Ask for one run (one at a time); the reply arrives on the events queue."""
        self.started = time.monotonic()
        self._deliver((token, parameters))

    def mark_ready(self) -> None:
        """The child is ready (its first message): a waiting run's clock starts now."""
        self.ready, self.started = True, time.monotonic()

    def deadline(self, timeout: float | None) -> float:
        """When the outstanding run must be stopped (``time.monotonic`` scale)."""
        if timeout is None:
            return math.inf
        if not self.ready:
            return self.born + STARTUP_LIMIT
        return self.started + timeout

    def timeout_outcome(self, timeout: float | None) -> dict:
        """Kill the child and describe the run it was late with."""
        self.kill()
        if not self.ready:
            message = f"the worker process did not start within {STARTUP_LIMIT:g} s"
        else:
            message = f"run exceeded the timeout of {timeout:g} s and was killed"
        return failure("timeout", message)

    def exit_description(self) -> tuple[str, int | None]:
        """Why the child ended (after its stdout closed): text and exit code."""
        self.kill()  # reaps it, and stops anything it started that is still running
        code = self.proc.returncode
        if code is not None and code < 0:
            with contextlib.suppress(ValueError):
                return f"killed by {signal.Signals(-code).name}", code
        return f"exit code {code}", code

    def kill(self) -> None:
        """Stop the child and everything it started, now."""
        if os.name == "posix":
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self.proc.pid, signal.SIGKILL)
        else:
            self.proc.kill()
        self.proc.wait()
        self._deliver(_STOP)

    def close(self) -> None:
        """Stop an idle child (it holds no state worth a graceful exit)."""
        self.kill()

    def run(self, token: str, parameters: dict[str, float], timeout: float | None) -> dict:
        """Run once and wait (for a sandbox with its own events queue)."""
        self.send(token, parameters)
        while True:
            deadline = self.deadline(timeout)
            wait = None if deadline == math.inf else max(0.0, deadline - time.monotonic())
            try:
                _, message = self.events.get(timeout=wait)
            except queue.Empty:
                return self.timeout_outcome(timeout)
            if message is None:
                return death_outcome(self)
            if message[0] is None:
                self.mark_ready()
                continue
            return message[1]


def death_outcome(sandbox: Sandbox) -> dict:
    """The outcome of a run whose worker died (its stdout closed)."""
    text, code = sandbox.exit_description()
    return failure("worker-died", f"the worker process died during the run ({text})", code)


def pickle_payload(simulator: Simulator, forcing: Forcing) -> bytes:
    """Pickle the simulator and boundary conditions once for all workers."""
    try:
        return pickle.dumps((simulator, forcing), protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as exc:
        raise SimulatorError(
            f"cannot send the simulator {qualname(simulator)} to worker processes: {exc}",
            hint="define simulator classes at module level, or use backend='serial'",
        ) from exc


# ------------------------------------------------------------ Dask tasks


_WORKER_SANDBOXES: dict[int, tuple[str, Sandbox]] = {}  # Dask worker: thread id -> sandbox
_WORKER_LOCK = threading.Lock()


def dask_task(
    payload: bytes, context: str, key: str, parameters: dict[str, float], timeout: float | None
) -> dict:
    """Runs on a Dask worker: one simulation in this thread's worker subprocess."""
    thread = threading.get_ident()
    with _WORKER_LOCK:
        entry = _WORKER_SANDBOXES.pop(thread, None)
    if entry is not None and entry[0] != context:
        entry[1].close()
        entry = None
    sandbox = entry[1] if entry is not None else Sandbox(payload, queue.Queue())
    outcome = sandbox.run(key, parameters, timeout)
    if outcome["ok"] or outcome["error"]["type"] not in ("timeout", "worker-died"):
        with _WORKER_LOCK:
            _WORKER_SANDBOXES[thread] = (context, sandbox)
    return outcome


def close_worker_sandboxes(context: str) -> int:
    """Runs on a Dask worker: close the sandboxes of one run_design call."""
    with _WORKER_LOCK:
        mine = [t for t, (c, _) in _WORKER_SANDBOXES.items() if c == context]
        sandboxes = [_WORKER_SANDBOXES.pop(t)[1] for t in mine]
    for sandbox in sandboxes:
        sandbox.close()
    return len(sandboxes)
