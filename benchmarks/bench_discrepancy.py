"""The difference-process phase alone, on a study folder that has run up to calibrate.

Runs ``bayescal.pipeline.run(study, until="discrepancy")`` on FOLDER: the
stages before it are reused (same stage keys), the discrepancy stage runs
(its key changes with the code's ``[discrepancy]`` settings, so a folder
written by an older bayescal recomputes it). Prints the stage's wall time
(``stages.json``), this process's wall and CPU time (worker processes
included), the load average, the phase's length, updates, whether it
converged, per parameter R-hat and bulk and tail ESS (theta* in physical
units), and the training MSE without and with Delta.

Run (after ``bayescal init box-coheating DIR`` and ``bayescal run DIR``, or on
a folder kept by ``bench_examples.py --keep``)::

    nice -n 10 .venv/bin/python benchmarks/bench_discrepancy.py DIR
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import json  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bayescal.config import load_study  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402


def cpu_seconds() -> float:
    """CPU seconds of this process and of its finished worker processes."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    folder = Path(sys.argv[1])
    load0 = os.getloadavg()[0]
    cpu0, start = cpu_seconds(), time.perf_counter()
    res = run(load_study(folder), until="discrepancy", options=Options())
    wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu0
    d = res.discrepancy
    if d is None:
        print(f"{folder}: [discrepancy] is not enabled")
        return 1
    stages = json.loads((res.context.out / "stages.json").read_text(encoding="utf-8"))
    diag = d.posterior.diagnostics
    t = len(d.posterior.names)
    print(
        f"{folder}: ran {', '.join(res.ran)}; discrepancy stage "
        f"{stages['discrepancy']['seconds']:.1f} s wall; this process {wall:.1f} s wall, "
        f"{cpu:.1f} s CPU; load average {load0:.1f} -> {os.getloadavg()[0]:.1f}"
    )
    chains, kept = d.posterior.unit_draws.shape[:2]
    print(f"  {chains} chains x {kept} kept, {d.updates} updates/chain, converged {d.converged}")
    for k in range(t):
        print(
            f"  {diag.names[k]:10s} R-hat {diag.rhat[k]:.4f} bulk ESS {diag.ess_bulk[k]:7.0f} "
            f"tail ESS {diag.ess_tail[k]:7.0f}"
        )
    print(
        f"  worst R-hat {np.nanmax(diag.rhat[:t]):.4f}, smallest bulk ESS "
        f"{np.nanmin(diag.ess_bulk[:t]):.0f}, tail ESS {np.nanmin(diag.ess_tail[:t]):.0f}"
    )
    for name, (model, corrected) in d.mse.items():
        print(f"  training MSE of {name}: {model:.4g} -> {corrected:.4g} with Delta")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
