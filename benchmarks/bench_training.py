"""Emulator training: gradient MAP search against the paper's MCMC, same process (issue 18).

Target of the issue: emulator training at R = 500 runs x m* = 200 periods x p = 5
bases at least 5 times faster than the Metropolis-within-Gibbs route at equal
quality (the same MAP log posterior within noise, the same leave-one-run-out
RMSE).

Data: the virtual wall of ``tests/helpers/virtual_wall.py`` with ``R``
Latin-hypercube runs over ``m*`` daily periods and exactly ``p`` output
components (as ``bench_scale.py``). Both trainings run in this process, one
after the other (``--order`` says which first), each with
``backend="processes"`` (what the pipeline uses on 2 cores):

* ``mcmc``: ``train(method="mcmc")`` at the study-file defaults: 2 chains x
  (500 + 1000) sweeps of Metropolis-within-Gibbs, best draw refined by L-BFGS-B;
* ``map``: ``train(method="map")``: multi-start L-BFGS-B with the exact gradient
  (starts on 64 runs, candidates polished on all), joint polish, Laplace
  approximation.

For each it prints the wall time, the CPU time (this process and its workers:
steadier than wall time on a shared machine), the log-scale log posterior at
the MAP (both evaluated by the same function), every basis's term, and the
leave-one-run-out RMSE (closed form); then the ratios.

BLAS and OpenMP are single-threaded (set before numpy is imported)::

    .venv/bin/python benchmarks/bench_training.py              # 500 x 200 x 5 (~15 min idle)
    .venv/bin/python benchmarks/bench_training.py --quick      # 60 x 30 x 3 (~1 min)
    .venv/bin/python benchmarks/bench_training.py --mcmc-sweeps 100 200   # shorter MCMC
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from bayescal.config import EmulatorSection  # noqa: E402
from bayescal.emulator.assemble import Assembled, assemble  # noqa: E402
from bayescal.emulator.gp import Emulator  # noqa: E402
from bayescal.emulator.gradient import LogScalePosterior  # noqa: E402
from bayescal.emulator.training import train  # noqa: E402
from virtual_wall import virtual_experiment  # noqa: E402

DEFAULTS = EmulatorSection()


def cpu_seconds() -> float:
    """CPU seconds of this process and of its finished worker processes."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


@dataclass(frozen=True)
class Trained:
    """One training and what it cost."""

    method: str
    emulator: Emulator
    wall: float
    cpu: float


def run(method: str, a: Assembled, sweeps: tuple[int, int], seed: int) -> Trained:
    cpu0, start = cpu_seconds(), time.perf_counter()
    em = train(
        a,
        method=method,  # type: ignore[arg-type]
        n_burn=sweeps[0],
        n_draws=sweeps[1],
        n_chains=2,
        seed=seed,
        backend="processes",
    )
    return Trained(method, em, time.perf_counter() - start, cpu_seconds() - cpu0)


def describe(t: Trained, post: LogScalePosterior) -> tuple[float, float]:
    """Print one training's line; return (log-scale log posterior at its MAP, LOO RMSE)."""
    em = t.emulator
    layout = post.layout
    u = np.log(layout.pack(em.beta, em.tau, em.lam))
    value = post.value(u)
    lam = math.exp(float(u[layout.lam_index]))
    terms = [post.basis(j, u[layout.block(j)], lam, grad=False).value for j in range(layout.p)]
    start = time.perf_counter()
    loo = em.loo_cv()
    took = time.perf_counter() - start
    rmse = float(np.sqrt(np.mean([v**2 for v in loo.rmse.values()])))
    print(
        f"  {t.method:5s} wall {t.wall:8.1f} s  CPU {t.cpu:8.1f} s  log posterior {value:.4f}  "
        f"LOO RMSE {rmse:.6g} ({took:.1f} s)"
    )
    print("        basis terms " + ", ".join(f"{v:.3f}" for v in terms) + f"; lambda {lam:.6g}")
    return value, rmse


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=500)
    parser.add_argument("--periods", type=int, default=200)
    parser.add_argument("--bases", type=int, default=5)
    parser.add_argument(
        "--mcmc-sweeps",
        type=int,
        nargs=2,
        default=(DEFAULTS.burn, DEFAULTS.samples),
        metavar=("BURN", "DRAWS"),
        help="MCMC burn-in and kept sweeps per chain (default: the study-file defaults)",
    )
    parser.add_argument("--order", choices=("map-first", "mcmc-first"), default="map-first")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--quick", action="store_true", help="60 x 30 x 3")
    opts = parser.parse_args()
    if opts.quick:
        opts.runs, opts.periods, opts.bases = 60, 30, 3
    print(
        f"emulator training, R = {opts.runs} runs x m* = {opts.periods} periods x "
        f"p = {opts.bases} bases; BLAS threads 1, {os.cpu_count()} CPUs, chains/bases in "
        f"worker processes; load average at start {os.getloadavg()[0]:.1f}"
    )
    start = time.perf_counter()
    ve = virtual_experiment(seed=0, runs=opts.runs, periods=opts.periods)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=opts.bases)
    print(f"  virtual wall + assemble: {time.perf_counter() - start:.1f} s (not counted)")
    sweeps = tuple(opts.mcmc_sweeps)
    methods = ["map", "mcmc"] if opts.order == "map-first" else ["mcmc", "map"]
    done = {m: run(m, a, sweeps, opts.seed) for m in methods}  # type: ignore[arg-type]
    post = LogScalePosterior(a.theta, a.x, a.w, a.basis.ktk, a.lam_prior)
    print(f"  mcmc: 2 chains x ({sweeps[0]} + {sweeps[1]}) sweeps; map: default settings")
    values = {m: describe(done[m], post) for m in ("mcmc", "map")}
    fast, slow = done["map"], done["mcmc"]
    print(
        f"  mcmc / map: wall {slow.wall / fast.wall:.1f}x, CPU {slow.cpu / fast.cpu:.1f}x; "
        f"log posterior map - mcmc {values['map'][0] - values['mcmc'][0]:+.4f}; "
        f"LOO RMSE map / mcmc {values['map'][1] / values['mcmc'][1]:.5f}"
    )
    print(f"  load average at end {os.getloadavg()[0]:.1f} (other jobs share the cores)")


if __name__ == "__main__":
    main()
