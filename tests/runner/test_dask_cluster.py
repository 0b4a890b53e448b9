"""A Dask cluster for real: ``dask scheduler`` and two ``dask worker`` processes on localhost.

Not a LocalCluster: the scheduler and the workers are separate programs, as on a
cluster of machines (docs/cluster.md has the recipe). The design runs with
``--scheduler tcp://127.0.0.1:PORT``; two of its runs are in the cache before,
and one worker is killed (SIGKILL) in the middle of a run. The runs must all
finish, each recorded once, the cached ones not run again, and the killed
worker's run taken over by the other worker. The simulator sleeps 1.5 s a run
and logs when each run starts and ends, and in which worker (``Logged``).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import sims_for_tests as sims
from bayescal.atomic import read_npz
from bayescal.design import Design, UniformPrior, latin_hypercube
from bayescal.runner import run_design
from bayescal.simulators.base import Forcing
from paths import HELPERS, REPO

pytest.importorskip("distributed")

N = 48
FORCING = Forcing(3600.0, {"temp_air_out": 10.0 + 5.0 * np.sin(np.arange(N) / 3.0)})
PRIORS = {"a": UniformPrior(0.0, 1.0), "b": UniformPrior(0.0, 0.2)}
DESIGN = latin_hypercube(PRIORS, 8, seed=4)
CACHED = 2  # runs put in the cache before the cluster run
DELAY = 1.5  # [s] per run: long enough to kill a worker in the middle of one
DASK = Path(sys.executable).with_name("dask")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _start(arguments: list[str], log: Path) -> subprocess.Popen[bytes]:
    env = os.environ | {
        "PYTHONPATH": os.pathsep.join([str(REPO / "src"), str(HELPERS)]),
        "OPENBLAS_NUM_THREADS": "1",
    }
    with open(log, "wb") as out:
        return subprocess.Popen(
            [str(DASK), *arguments], stdout=out, stderr=subprocess.STDOUT, env=env
        )


@contextlib.contextmanager
def _cluster(folder: Path) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """A scheduler and two single-thread workers without nannies (a killed one stays dead)."""
    from distributed import Client

    address = f"tcp://127.0.0.1:{_free_port()}"
    port = address.rsplit(":", 1)[1]
    started = [_start(["scheduler", "--host", "127.0.0.1", "--port", port, "--no-dashboard"],
                      folder / "scheduler.log")]  # fmt: skip
    try:
        for k in range(2):
            started.append(
                _start(
                    ["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                     "--name", f"w{k}", "--death-timeout", "60"],
                    folder / f"worker{k}.log",
                )
            )  # fmt: skip
        deadline = time.monotonic() + 90
        while True:  # the scheduler may not listen yet
            try:
                with Client(address, timeout=5) as client:
                    client.wait_for_workers(2, timeout=max(1.0, deadline - time.monotonic()))
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        yield address, started[1:]
    finally:
        for proc in reversed(started):  # only the processes this test started
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in started:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _events(log: Path) -> list[tuple[str, tuple[float, float], int]]:
    if not log.is_file():
        return []
    found = []
    for line in log.read_text(encoding="utf-8").splitlines():
        event, a, b, pid = line.split()
        found.append((event, (float(a), float(b)), int(pid)))
    return found


@pytest.mark.timeout(300)
def test_design_on_a_dask_cluster_survives_a_killed_worker(tmp_path: Path) -> None:
    log = tmp_path / "runs.log"
    simulator = sims.Logged(log=str(log), delay=DELAY)
    cache = tmp_path / "cache"
    first = Design(PRIORS, DESIGN.unit[:CACHED])
    run_design(simulator, FORCING, first, cache_dir=cache, backend="serial")
    log.unlink()

    killer_done: dict[str, object] = {}
    with _cluster(tmp_path) as (address, workers):
        pids = {w.pid: w for w in workers}

        def kill_mid_run() -> None:
            # Kill the first worker seen starting a run, half-way through that run.
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                started = [(run, pid) for event, run, pid in _events(log) if event == "start"]
                if started:
                    run, pid = started[0]
                    time.sleep(DELAY / 2)
                    os.kill(pid, signal.SIGKILL)
                    pids[pid].wait()
                    killer_done.update(run=run, pid=pid)
                    return
                time.sleep(0.05)

        import threading

        killer = threading.Thread(target=kill_mid_run, daemon=True)
        killer.start()
        results = run_design(
            simulator, FORCING, DESIGN, cache_dir=cache, backend="dask", scheduler=address
        )
        killer.join(timeout=5)

    assert killer_done, "no worker was killed: the design finished before any run started"
    killed_run, killed_pid = killer_done["run"], killer_done["pid"]
    # every run finished, none failed; the two cached ones were not run again
    assert (results.n_cached, results.n_run, results.n_failed) == (CACHED, 8 - CACHED, 0)
    events = _events(log)
    cached = {tuple(map(float, row)) for row in DESIGN.values[:CACHED]}
    assert not {run for _, run, _ in events} & cached
    # each run is recorded once in the cache, at its first attempt as the runner saw it
    stored = sorted((cache / "runs").glob("*.npz"))
    assert len(stored) == 8
    for path in stored:
        assert json.loads(str(read_npz(path)["metadata"]))["attempts"] == 1
    # each run completed exactly once; the killed worker's run was retried on the other one
    done = Counter(run for event, run, _ in events if event == "done")
    assert set(done) == {tuple(map(float, row)) for row in DESIGN.values[CACHED:]}
    assert max(done.values()) == 1
    finished_by = {run: pid for event, run, pid in events if event == "done"}
    assert finished_by[killed_run] != killed_pid
    # the results are those of the simulator, row by row
    for row, i in enumerate(results.indices):
        ref = sims.reference(*DESIGN.values[i], FORCING)
        np.testing.assert_allclose(results.outputs["y"][row], ref["y"], rtol=1e-12)
