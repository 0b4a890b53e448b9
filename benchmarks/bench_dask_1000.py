"""1000 runs of the paper's wall through the Dask backend on 2 workers (issue 7).

The built-in :class:`~bayescal.simulators.wall.MultilayerWall` of the paper
(glass-fibre board | aerated concrete | glass-fibre board, imposed surface
temperatures, ``tests/helpers/virtual_wall.py``) over 1644 half-hourly samples, a
Latin hypercube of 1000 parameter sets over the paper's priors, through
:func:`bayescal.runner.run_design` with ``backend="dask"`` on a
``LocalCluster`` of 2 single-threaded worker processes (started once before
the timing; its start-up is printed separately). Every run is written to the
per-run cache (an empty temporary folder), as in a real study.

Prints runs per second for Dask x2 and for the serial backend measured in the
same process on a subset (``--serial-runs``), their ratio, and whether the
1000 runs took less than the issue's 2 minutes. Run::

    .venv/bin/python benchmarks/bench_dask_1000.py
    .venv/bin/python benchmarks/bench_dask_1000.py --runs 200 --serial-runs 50   # quick
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from bayescal.design import latin_hypercube  # noqa: E402
from bayescal.runner import run_design  # noqa: E402
from bayescal.simulators.base import Forcing  # noqa: E402
from virtual_wall import PRIORS, STEP, paper_wall, surface_temperatures  # noqa: E402

N_SAMPLES = 1644
TARGET_SECONDS = 120.0


def _timed(n_runs: int, forcing: Forcing, seed: int, **options: Any) -> float:
    """Wall seconds of ``run_design`` for ``n_runs`` fresh runs (empty cache)."""
    design = latin_hypercube(PRIORS, n_runs, seed=seed)
    with tempfile.TemporaryDirectory() as cache:
        start = time.perf_counter()
        results = run_design(paper_wall(), forcing, design, cache_dir=cache, **options)
        elapsed = time.perf_counter() - start
    if results.n_run != n_runs:
        raise RuntimeError(f"{results.n_failed} runs failed: {results.failures[:1]}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--serial-runs", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    opts = parser.parse_args()

    from distributed import LocalCluster

    forcing = Forcing(STEP, surface_temperatures(np.random.default_rng(0), N_SAMPLES))
    print(
        f"paper wall, {N_SAMPLES} half-hourly samples; {len(os.sched_getaffinity(0))} cores, "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    t_serial = _timed(opts.serial_runs, forcing, seed=1, backend="serial")
    rate_serial = opts.serial_runs / t_serial
    print(f"  serial: {opts.serial_runs} runs in {t_serial:.1f} s = {rate_serial:.1f} runs/s")

    start = time.perf_counter()
    cluster = LocalCluster(
        n_workers=opts.workers, threads_per_worker=1, processes=True, dashboard_address=":0"
    )
    t_start = time.perf_counter() - start
    with cluster:
        t_dask = _timed(
            opts.runs, forcing, seed=2, backend="dask", scheduler=cluster.scheduler_address
        )
    rate_dask = opts.runs / t_dask
    print(
        f"  dask x{opts.workers}: {opts.runs} runs in {t_dask:.1f} s = {rate_dask:.1f} runs/s "
        f"(LocalCluster start-up {t_start:.1f} s, not included)"
    )
    print(
        f"  dask x{opts.workers} / serial: {rate_dask / rate_serial:.2f} "
        f"(parallel efficiency {rate_dask / (opts.workers * rate_serial):.2f})"
    )
    verdict = "met" if t_dask + t_start < TARGET_SECONDS else "MISSED"
    print(
        f"  {opts.runs} runs including cluster start-up: {t_dask + t_start:.1f} s; "
        f"target {TARGET_SECONDS:.0f} s for 1000 runs: {verdict}"
        + ("" if opts.runs == 1000 else " (fewer runs than the target's 1000)")
    )
    print(f"  load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
