"""Run a simulator over a design, many runs at a time, cached per run and resumable.

Each run (one row of the design) is identified by a key, the SHA-256 of the
simulator's configuration, the boundary conditions and the run's parameter
values (:mod:`bayescal.runner.keys`). A finished run is written at once,
atomically, to ``cache_dir/runs/<key>.npz`` (outputs, parameters, metadata); a
run that failed after all its attempts is described in
``cache_dir/failures/<key>.json`` (:mod:`bayescal.runner.cache`). Calling
:func:`run_design` again with the same inputs loads the finished runs and runs
only the missing ones (failed runs are tried again: a failure is not cached).

Backends
--------
``"serial"``
    Runs in the calling process, one after the other. For debugging: no
    timeout, and a simulator that kills its process kills the caller.
``"processes"`` (default)
    ``jobs`` worker processes on this machine, each a fresh Python
    interpreter (``subprocess``) that receives the simulator and the
    boundary conditions once and then runs one parameter set at a time.
    Each worker runs in its own process group, so a run that exceeds
    ``timeout`` is stopped for real: the group (the worker and any external
    program it started) gets ``SIGKILL`` and a new worker takes its place.
    A worker that dies (``os._exit``, a segfault, the OOM killer) costs only
    its current run.
``"dask"``
    Tasks on a Dask distributed cluster: a ``LocalCluster`` created and
    closed here when ``scheduler`` is ``None``, else the scheduler at that
    address. Each Dask worker thread runs its simulations in the same kind
    of worker subprocess as above (kept between tasks), so timeouts and
    crashes are handled the same way and never take a Dask worker down.

The clock of ``timeout`` starts once a worker has loaded the simulator (see
:mod:`bayescal.runner.sandbox`), so slow imports do not count against a run.
Results come back to the calling process, which alone writes the cache, so
remote Dask workers need no shared file system.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import math
import os
import queue
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from bayescal import __version__
from bayescal.errors import ConfigError
from bayescal.runner import sandbox as workers
from bayescal.runner.cache import Ledger, Progress, load_run
from bayescal.runner.keys import forcing_fingerprint, qualname, run_key, simulator_fingerprint
from bayescal.simulators.base import Forcing, Simulator

if TYPE_CHECKING:  # not at run time: worker processes start faster without scipy.stats
    from bayescal.design import Design

__all__ = ["BACKENDS", "Backend", "RunFailure", "RunResults", "run_design"]

Backend = Literal["serial", "processes", "dask"]
BACKENDS: tuple[str, ...] = ("serial", "processes", "dask")


# ----------------------------------------------------------------------- results


@dataclass(frozen=True)
class RunFailure:
    """A design row whose run failed after all its attempts.

    Parameters
    ----------
    index
        Row of the design.
    key
        Cache key of the run.
    parameters
        Parameter values of the row, in physical units.
    error_type
        Exception class (``module.Class``), ``"timeout"`` or ``"worker-died"``.
    message
        One-line error message of the last attempt.
    attempts
        Number of attempts made.
    exit_code
        Exit status of an external program or of the dead worker, if known.
    stderr
        Tail of an external program's standard error, if the error carried it.
    """

    index: int
    key: str
    parameters: dict[str, float]
    error_type: str
    message: str
    attempts: int
    exit_code: int | None = None
    stderr: str | None = None


@dataclass(frozen=True)
class RunResults:
    """The successful runs of a design, stacked, and the failed ones.

    Parameters
    ----------
    design
        The design that was run (all rows).
    indices
        Design rows that succeeded, ascending, shape ``(R_ok,)``.
    outputs
        Output name -> array of shape ``(R_ok, n)``; row ``i`` belongs to design
        row ``indices[i]``.
    keys
        Cache key of each successful row.
    failures
        Failed rows, ascending by row.
    n_run
        Rows whose result was computed by this call.
    n_cached
        Rows whose result was loaded from the cache.
    n_attempts
        Simulator invocations made by this call, failed ones and retries included.
    damaged
        Keys of cached runs whose file could not be read (truncated, damaged): they
        were run again, never used.
    """

    design: Design
    indices: np.ndarray
    outputs: dict[str, np.ndarray]
    keys: tuple[str, ...]
    failures: tuple[RunFailure, ...]
    n_run: int
    n_cached: int
    n_attempts: int
    damaged: tuple[str, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, in column order."""
        return self.design.names

    @property
    def parameters(self) -> np.ndarray:
        """Physical parameter values of the successful rows, shape ``(R_ok, t)``."""
        return self.design.values[self.indices]

    @property
    def unit(self) -> np.ndarray:
        """Normalised parameter values of the successful rows, shape ``(R_ok, t)``."""
        return self.design.unit[self.indices]

    @property
    def n_failed(self) -> int:
        """Number of failed rows."""
        return len(self.failures)


# ---------------------------------------------------------------------- backends


def _run_serial(simulator: Simulator, forcing: Forcing, todo: list[str], ledger: Ledger) -> None:
    for key in todo:
        while ledger.record(key, workers.execute(simulator, forcing, ledger.parameters[key])):
            pass


def _run_processes(
    payload: bytes, todo: list[str], ledger: Ledger, jobs: int, timeout: float | None
) -> None:
    events: queue.Queue[tuple[int, Any]] = queue.Queue()
    pending = deque(todo)
    idle: list[workers.Sandbox] = []
    busy: dict[int, tuple[workers.Sandbox, str]] = {}  # sid -> (sandbox, key of its run)
    slots = min(jobs, len(pending))

    def dispatch() -> None:
        while pending and (idle or len(busy) < slots):
            sandbox = idle.pop() if idle else workers.Sandbox(payload, events)
            key = pending.popleft()
            sandbox.send(key, ledger.parameters[key])
            busy[sandbox.sid] = (sandbox, key)

    try:
        while pending or busy:
            dispatch()
            first = min(sandbox.deadline(timeout) for sandbox, _ in busy.values())
            wait = None if first == math.inf else max(0.0, first - time.monotonic())
            finished: list[tuple[str, dict]] = []
            with contextlib.suppress(queue.Empty):
                sid, message = events.get(timeout=wait)
                if sid in busy:  # else: a stale event from a sandbox already replaced
                    sandbox, key = busy[sid]
                    if message is None:
                        del busy[sid]
                        finished.append((key, workers.death_outcome(sandbox)))
                    elif message[0] is None:
                        sandbox.mark_ready()
                    else:
                        del busy[sid]
                        idle.append(sandbox)
                        finished.append((key, message[1]))
            now = time.monotonic()
            for sid, (sandbox, key) in list(busy.items()):
                if now >= sandbox.deadline(timeout):
                    del busy[sid]
                    finished.append((key, sandbox.timeout_outcome(timeout)))
            dispatch()  # keep the workers busy while the results are written
            for key, outcome in finished:
                if ledger.record(key, outcome):
                    pending.append(key)
    finally:
        for sandbox, _ in busy.values():
            sandbox.kill()
        for sandbox in idle:
            sandbox.close()


def _run_dask(
    payload: bytes,
    context: str,
    todo: list[str],
    ledger: Ledger,
    jobs: int,
    timeout: float | None,
    scheduler: str | None,
) -> None:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        raise ConfigError(
            "backend 'dask' needs the dask distributed package, which is not installed",
            hint="pip install 'bayescal[dask]'",
        ) from exc
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            cluster = LocalCluster(
                n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=":0"
            )
            stack.enter_context(cluster)
            client = stack.enter_context(Client(cluster))
        else:
            client = stack.enter_context(Client(scheduler))
        shared = client.scatter(payload, broadcast=True, hash=False)
        attempt = itertools.count()

        def submit(key: str) -> Any:
            name = f"bayescal-run-{key[:16]}-{next(attempt)}"
            params = ledger.parameters[key]
            return client.submit(workers.dask_task, shared, context, key, params, timeout, key=name)

        try:
            _collect_dask(as_completed, submit, todo, ledger)
        finally:
            if scheduler is not None:  # a LocalCluster takes its workers' sandboxes with it
                client.run(workers.close_worker_sandboxes, context)


def _collect_dask(
    as_completed: Any, submit: Callable[[str], Any], todo: list[str], ledger: Ledger
) -> None:
    """Book the Dask futures as they finish; resubmit runs to retry."""
    futures = {submit(key): key for key in todo}
    running = as_completed(list(futures))
    for future in running:
        key = futures.pop(future)
        try:
            outcome = future.result()
        except Exception as exc:  # the task itself failed (e.g. its Dask worker died)
            outcome = {"ok": False, "seconds": math.nan, "error": workers.error_record(exc)}
        future.release()
        if ledger.record(key, outcome):
            retry = submit(key)
            futures[retry] = key
            running.add(retry)


# ---------------------------------------------------------------------- the API


def _check_options(
    backend: str, jobs: int | None, scheduler: str | None, timeout: float | None, retries: int
) -> int:
    if backend not in BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; expected one of {list(BACKENDS)}")
    if scheduler is not None and backend != "dask":
        raise ConfigError(
            f"a scheduler address needs backend='dask', got backend={backend!r}",
            hint="set backend = 'dask' or remove the scheduler address",
        )
    if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
        raise ConfigError(f"timeout must be a positive number of seconds, got {timeout!r}")
    if timeout is not None and backend == "serial":
        raise ConfigError(
            "backend 'serial' cannot stop a run that exceeds the timeout",
            hint="use backend='processes' (jobs=1 runs one at a time) or remove the timeout",
        )
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ConfigError(f"retries must be a non-negative integer, got {retries!r}")
    if jobs is None:
        if hasattr(os, "sched_getaffinity"):
            return max(1, len(os.sched_getaffinity(0)))
        return os.cpu_count() or 1
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigError(f"jobs must be a positive integer, got {jobs!r}")
    return jobs


def _check_simulator(simulator: Simulator, forcing: Forcing, design: Design) -> None:
    unknown = [name for name in design.names if name not in simulator.parameter_names]
    if unknown:
        raise ConfigError(
            f"design parameter(s) {unknown} are not parameters of {qualname(simulator)}, "
            f"which accepts {list(simulator.parameter_names)}"
        )
    forcing.require(tuple(simulator.input_names), qualname(simulator))


def run_design(
    simulator: Simulator,
    forcing: Forcing,
    design: Design,
    *,
    cache_dir: str | os.PathLike[str],
    backend: Backend = "processes",
    jobs: int | None = None,
    scheduler: str | None = None,
    timeout: float | None = None,
    retries: int = 0,
    progress: Progress | None = None,
) -> RunResults:
    """Run the simulator at every row of a design, reusing cached runs.

    Parameters
    ----------
    simulator
        The simulator (picklable, for the ``"processes"`` and ``"dask"`` backends).
    forcing
        Boundary conditions, the same for every run.
    design
        Parameter sets to run; its names must be parameters of the simulator.
    cache_dir
        Folder of the per-run cache (``runs/``, ``failures/``); created if missing.
    backend
        ``"processes"``, ``"serial"`` or ``"dask"`` (see the module docstring).
    jobs
        Number of worker processes (``"processes"``) or of ``LocalCluster``
        workers (``"dask"`` without ``scheduler``); default: one per CPU core.
    scheduler
        Address of a Dask scheduler (``"tcp://host:8786"``); ``None`` with
        ``backend="dask"`` starts a ``LocalCluster``.
    timeout
        Wall-clock limit of one attempt; a run past it is killed and counts as
        failed. ``None``: no limit. [s]
    retries
        Further attempts for a failed run before it is given up.
    progress
        Called as ``progress(done, failed, total)`` once the cache is read and
        after every finished or failed run (see :func:`bayescal.cli.progress.simulation_bar`).

    Returns
    -------
    RunResults
        Successful rows stacked per output; failed rows listed with their
        errors. Failed rows are dropped whole, so the grid of runs by samples
        stays complete; how many failures are acceptable is the caller's call.
    """
    jobs = _check_options(backend, jobs, scheduler, timeout, retries)
    _check_simulator(simulator, forcing, design)
    cache = Path(cache_dir)
    sim_fp, forcing_fp = simulator_fingerprint(simulator), forcing_fingerprint(forcing)
    values = design.values
    rows = [dict(zip(design.names, map(float, v), strict=True)) for v in values]
    keys = [run_key(sim_fp, forcing_fp, row) for row in rows]
    metadata = {
        "simulator": qualname(simulator),
        "simulator_fingerprint": sim_fp,
        "forcing_fingerprint": forcing_fp,
        "bayescal": __version__,
    }
    ledger = Ledger(
        cache_dir=cache,
        parameters=dict(zip(keys, rows, strict=True)),
        weight={key: keys.count(key) for key in keys},
        retries=retries,
        progress=progress,
        total=design.runs,
        metadata=metadata,
    )
    names, n = tuple(simulator.output_names), forcing.n
    todo, damaged = [], []
    for key in ledger.parameters:
        path = cache / "runs" / f"{key}.npz"
        cached = load_run(path, names, n)
        if cached is None:
            todo.append(key)
            if path.is_file():  # there, but truncated or damaged: run again, never used
                damaged.append(key)
        else:
            ledger.loaded(key, cached)
    n_cached = ledger.done
    ledger.report()
    if todo and backend == "serial":
        _run_serial(simulator, forcing, todo, ledger)
    elif todo and backend == "processes":
        _run_processes(workers.pickle_payload(simulator, forcing), todo, ledger, jobs, timeout)
    elif todo:
        context = hashlib.sha256(f"{sim_fp}{forcing_fp}{time.time_ns()}".encode()).hexdigest()
        payload = workers.pickle_payload(simulator, forcing)
        _run_dask(payload, context, todo, ledger, jobs, timeout, scheduler)
    return _collect(design, keys, ledger, names, n, n_cached, tuple(damaged))


def _collect(
    design: Design,
    keys: list[str],
    ledger: Ledger,
    names: tuple[str, ...],
    n: int,
    n_cached: int,
    damaged: tuple[str, ...] = (),
) -> RunResults:
    ok = [i for i, key in enumerate(keys) if key in ledger.outputs]
    outputs = {
        name: np.stack([ledger.outputs[keys[i]][name] for i in ok]) if ok else np.empty((0, n))
        for name in names
    }
    failures = []
    for i, key in enumerate(keys):
        if key not in ledger.outputs:
            last = ledger.errors[key][-1]
            failure = RunFailure(
                index=i,
                key=key,
                parameters=ledger.parameters[key],
                error_type=last["type"],
                message=last["message"],
                attempts=len(ledger.errors[key]),
                exit_code=last.get("exit_code"),
                stderr=last.get("stderr"),
            )
            failures.append(failure)
    return RunResults(
        design=design,
        indices=np.array(ok, dtype=int),
        outputs=outputs,
        keys=tuple(keys[i] for i in ok),
        failures=tuple(failures),
        n_run=len(ok) - n_cached,
        n_cached=n_cached,
        n_attempts=ledger.attempts,
        damaged=damaged,
    )
