"""The quick benchmark set behind ``make bench``.

Runs, each in its own process so thread settings and imports stay clean:

* ``bench_simulators.py``: built-in wall and test box, time per run and ratio to targets;
* ``bench_algebra.py --skip-large-dense``: calibration log-density, dense vs Kronecker
  at the paper's size, Kronecker alone at R = 200 x m* = 100;
* ``bench_runner.py``: runs per second, serial vs 2 workers (processes, Dask);
* ``bench_floor.py --quick``: log-density time against its unavoidable operations;
* ``bench_scale.py --quick``: the scale benchmark at a CI size;
* ``bench_training.py --quick``: emulator training, gradient MAP search vs MCMC;
* ``bench_vectorised.py --quick``: lockstep (vectorised) chains against serial ones;
* ``bench_hmc.py --quick``: NUTS against Metropolis-within-Gibbs, bulk ESS of theta*
  per CPU second (skipped with a message where the ``hmc`` extra is missing);
* ``bench_moves.py --gibbs 1000 2000``: one-at-a-time sweeps against joint moves,
  unscreened and screened, on the Twin House calibration, bulk ESS per evaluation
  and per second (shorter Gibbs chains than the script's default; skipped with a
  message where the shared Annex 58 data are missing);
* ``bench_seqdesign.py --quick``: runs to posterior on the wall, one-shot designs of 8,
  15 and 30 runs against a sequential one (about a minute; the full set, with the
  co-heating box, is ``bench_seqdesign.py`` alone);
* ``bench_examples.py``: every worked example end to end, the examples table (the
  EnergyPlus ``office`` example is listed as not run, with the reason: about 15
  minutes of screening, runs and calibration; ``bench_examples.py --office`` runs it).

Every script's output is shown as it runs; at the end the key lines are
printed again together: the dense / Kronecker ratios, the lockstep / serial
ratios, the training ratio, and the examples table.

BLAS is single-threaded (``OPENBLAS_NUM_THREADS=1``, ``OMP_NUM_THREADS=1``).
Full-size variants are run by calling the scripts directly (see docs/benchmarks.md).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
QUICK = [
    ["bench_simulators.py"],
    ["bench_algebra.py", "--skip-large-dense"],
    ["bench_runner.py", "--scale", "0.5"],
    ["bench_floor.py", "--quick"],
    ["bench_scale.py", "--quick"],
    ["bench_training.py", "--quick"],
    ["bench_vectorised.py", "--quick"],
    ["bench_hmc.py", "--quick"],
    ["bench_moves.py", "--gibbs", "1000", "2000"],
    ["bench_seqdesign.py", "--quick"],
    ["bench_examples.py"],
]
#: Lines repeated in the summary: (script, text the line contains).
KEY_LINES = [
    ("bench_algebra.py", "R = "),
    ("bench_algebra.py", "ratio dense / kronecker"),
    ("bench_training.py", "emulator training, R ="),
    ("bench_training.py", "mcmc / map"),
    ("bench_vectorised.py", "=== R = "),
    ("bench_vectorised.py", "lockstep / serial"),
    ("bench_moves.py", "joint / gibbs"),
    ("bench_moves.py", "joint / joint, unscreened"),
]


def main() -> int:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    status = 0
    outputs: dict[str, list[str]] = {}
    start = time.perf_counter()
    for args in QUICK:
        script = HERE / args[0]
        if not script.exists():
            print(f"-- {args[0]}: missing, skipped", flush=True)
            continue
        print(f"\n== {' '.join(args)}", flush=True)
        proc = subprocess.Popen(
            [sys.executable, str(script), *args[1:]],
            cwd=HERE,
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            print(line, end="", flush=True)
            lines.append(line.rstrip("\n"))
        status = status or proc.wait()
        outputs[args[0]] = lines
    print(f"\n== summary (make bench, {time.perf_counter() - start:.0f} s in all)")
    for script, text in KEY_LINES:
        for line in outputs.get(script, []):
            if text in line:
                print(f"[{script}] {line.strip()}")
    table = outputs.get("bench_examples.py", [])
    if "" in table:
        print("\n".join(table[table.index("") :]))
    return status


if __name__ == "__main__":
    raise SystemExit(main())
