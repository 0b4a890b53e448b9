"""The quick benchmark set behind ``make bench`` (a few minutes on 2 cores).

Runs, each in its own process so thread settings and imports stay clean:

* ``bench_simulators.py``: built-in wall and test box, time per run and ratio to targets;
* ``bench_algebra.py --skip-large-dense``: calibration log-density, dense vs Kronecker
  at the paper's size, Kronecker alone at R = 200 x m* = 100;
* ``bench_runner.py``: runs per second, serial vs 2 workers (processes, Dask);
* ``bench_floor.py --quick``: log-density time against its unavoidable operations;
* ``bench_scale.py --quick``: the scale benchmark at a CI size;
* ``bench_vectorised.py --quick``: lockstep (vectorised) chains against serial ones;
* ``bench_hmc.py --quick``: NUTS against Metropolis-within-Gibbs, bulk ESS of theta*
  per CPU second (skipped with a message where the ``hmc`` extra is missing).

BLAS is single-threaded (``OPENBLAS_NUM_THREADS=1``, ``OMP_NUM_THREADS=1``).
Full-size variants are run by calling the scripts directly (see docs/benchmarks.md).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
QUICK = [
    ["bench_simulators.py"],
    ["bench_algebra.py", "--skip-large-dense"],
    ["bench_runner.py", "--scale", "0.5"],
    ["bench_floor.py", "--quick"],
    ["bench_scale.py", "--quick"],
    ["bench_vectorised.py", "--quick"],
    ["bench_hmc.py", "--quick"],
]


def main() -> int:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    status = 0
    for args in QUICK:
        script = HERE / args[0]
        if not script.exists():
            print(f"-- {args[0]}: missing, skipped", flush=True)
            continue
        print(f"\n== {' '.join(args)}", flush=True)
        done = subprocess.run([sys.executable, str(script), *args[1:]], cwd=HERE, env=env)
        status = status or done.returncode
    return status


if __name__ == "__main__":
    raise SystemExit(main())
