"""Vectorised (lockstep) chains against serial and process chains (issue 7).

Calibration of theta*, lambda and lambda* (eq. 16) on the virtual wall of
``tests/helpers/virtual_wall.py`` (basis at 99 % of the variance, emulator trained as
in ``bench_calibration.py``), with the Metropolis-within-Gibbs settings of
``bayescal.calibration.posterior`` (batches of 25, adaptation cap 0.25), at the
paper's size (R = 30 runs x m* = 25 periods) and a medium one (R = 200 x m* =
100). For each size it runs

* ``serial``: 4 chains one after the other in this process;
* ``vectorised``: 4, 8 and 16 chains in lockstep in this process (one batched
  likelihood call per coordinate update);
* ``processes``: 4 chains in 2 worker processes (2 cores), pool start included;
* ``vectorised-processes``: 4 chains as 2 lockstep groups of 2, one per worker
  process (what the default ``backend="auto"`` runs here on 2 cores);

and prints the wall time, the CPU time (this process and its workers), the
seconds per 1000 sweeps per chain (wall time / total sweeps of all chains x
1000), the bulk ESS per second of theta* (the smallest over the t parameters,
ESS of all chains together / wall time) and the ratios to the serial run. Only
ratios measured in this run are printed: SEPIA's figure from issue 18 (35.8 s per
1000 sweeps of one chain at the paper's size, measured on another day) is quoted
beside the lockstep figure as a reference with its source, never divided into it
(docs/benchmarks.md compares the two where both were measured in one run).
Each configuration is repeated ``--repeats`` times, the repeats interleaved
(all configurations once, then again) so that a change of machine load hits
all of them alike; medians are printed.

BLAS and OpenMP are single-threaded (set before numpy is imported)::

    .venv/bin/python benchmarks/bench_vectorised.py            # ~3 minutes
    .venv/bin/python benchmarks/bench_vectorised.py --quick    # < 1 minute
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from bayescal.calibration.kron import make_algebra  # noqa: E402
from bayescal.calibration.target import CalibrationPosterior, default_sampler, default_starts  # noqa: E402
from bayescal.emulator.assemble import Assembled, assemble  # noqa: E402
from bayescal.emulator.gp import Emulator  # noqa: E402
from bayescal.emulator.training import train  # noqa: E402
from bayescal.mcmc.chains import run_chains  # noqa: E402
from bayescal.mcmc.diagnostics import import_arviz  # noqa: E402
from virtual_wall import virtual_experiment  # noqa: E402


@dataclass(frozen=True)
class Config:
    """One way of running the chains."""

    backend: str
    n_chains: int

    @property
    def label(self) -> str:
        return f"{self.backend} x{self.n_chains}"


CONFIGS = (
    Config("serial", 4),
    Config("vectorised", 4),
    Config("vectorised", 8),
    Config("vectorised", 16),
    Config("processes", 4),
    Config("vectorised-processes", 4),
)
SEPIA_SECONDS = 35.8  # per 1000 sweeps of one chain at the paper's size (issue 18)
#: The paper's size here (runs, periods; SEPIA's figure: 30 x 24): the lockstep figure is
#: compared with it there only.
SEPIA_SIZE = (30, 25)


def cpu_seconds() -> float:
    """CPU seconds of this process and of its finished worker processes."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def build(runs: int, periods: int) -> tuple[Emulator, Assembled]:
    """Simulate, assemble and train the emulator as bench_calibration.py does."""
    ve = virtual_experiment(seed=0, runs=runs, periods=periods)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, variance=0.99)
    return train(a, seed=1), a


def target(em: Emulator, a: Assembled) -> CalibrationPosterior:
    """A fresh calibration posterior (cold memos)."""
    alg = make_algebra("kronecker", em.theta, em.x, em.kernels, em.basis.ktk, em.w, a.w_star)
    return CalibrationPosterior(alg, list(a.priors.values()), em.lam_prior, a.lam_star_prior)


def run_one(
    cfg: Config, em: Emulator, a: Assembled, n_burn: int, n_draws: int
) -> tuple[float, float, float]:
    """Wall time, CPU time and smallest bulk ESS of theta* of one run."""
    post = target(em, a)
    cpu0 = cpu_seconds()
    start = time.perf_counter()
    chains = run_chains(
        default_sampler(post, n_burn),
        post,
        default_starts(post, cfg.n_chains, 3),
        n_draws,
        seed=3,
        backend=cfg.backend,  # type: ignore[arg-type]
        max_workers=2,
    )
    took = time.perf_counter() - start
    cpu = cpu_seconds() - cpu0
    az = import_arviz()
    values = [float(az.ess(chains.draws[:, :, k], method="bulk")) for k in range(post.t)]
    return took, cpu, min(values)


def run_case(runs: int, periods: int, n_burn: int, n_draws: int, repeats: int) -> None:
    """Build one problem size and time every configuration, interleaved."""
    start = time.perf_counter()
    em, a = build(runs, periods)
    print(
        f"\n=== R = {runs} runs x m* = {periods} periods, p = {a.basis.p} "
        f"(built in {time.perf_counter() - start:.1f} s); {n_burn} burn-in + {n_draws} "
        f"kept sweeps per chain, {repeats} interleaved repeats, medians ==="
    )
    times: dict[Config, list[float]] = {c: [] for c in CONFIGS}
    cpus: dict[Config, list[float]] = {c: [] for c in CONFIGS}
    ess: dict[Config, list[float]] = {c: [] for c in CONFIGS}
    for _ in range(repeats):
        for cfg in CONFIGS:
            took, cpu, e = run_one(cfg, em, a, n_burn, n_draws)
            times[cfg].append(took)
            cpus[cfg].append(cpu)
            ess[cfg].append(e)
    base = CONFIGS[0]
    base_time = statistics.median(times[base])
    base_rate = statistics.median(e / t for e, t in zip(ess[base], times[base], strict=True))
    base_per = 1e3 * base_time / (base.n_chains * (n_burn + n_draws))
    print(
        f"  {'configuration':26s} {'wall [s]':>9s} {'CPU [s]':>8s} {'s/1000 sweeps':>14s} "
        f"{'speed-up':>9s} {'min ESS':>8s} {'ESS/s':>8s} {'ESS/s ratio':>12s}"
    )
    for cfg in CONFIGS:
        wall = statistics.median(times[cfg])
        per = 1e3 * wall / (cfg.n_chains * (n_burn + n_draws))
        rate = statistics.median(e / t for e, t in zip(ess[cfg], times[cfg], strict=True))
        print(
            f"  {cfg.label:26s} {wall:9.2f} {statistics.median(cpus[cfg]):8.2f} {per:14.3f} "
            f"{base_per / per:9.2f} {statistics.median(ess[cfg]):8.0f} {rate:8.0f} "
            f"{rate / base_rate:12.2f}"
        )
    lock = CONFIGS[1]
    lock_per = 1e3 * statistics.median(times[lock]) / (lock.n_chains * (n_burn + n_draws))
    line = (
        f"  lockstep / serial: {base_per / lock_per:.2f}x per chain-sweep "
        f"({lock.label}: {lock_per:.3f} s per 1000 sweeps per chain, serial {base_per:.3f} s)"
    )
    if (runs, periods) == SEPIA_SIZE:
        # SEPIA's figure is for the paper's size only; other sizes have no reference here
        line += (
            f"; for reference, not measured here: SEPIA {SEPIA_SECONDS} s per 1000 sweeps "
            "of one chain (issue 18, 2026-11, another run)"
        )
    print(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short runs, one repeat")
    parser.add_argument("--repeats", type=int, default=3)
    opts = parser.parse_args()
    print(
        f"threads: OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}, "
        f"OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}; cpus: {os.cpu_count()}; "
        f"load average at start: {os.getloadavg()[0]:.2f}"
    )
    if opts.quick:
        run_case(30, 25, 100, 200, 1)
        run_case(200, 100, 50, 100, 1)
    else:
        run_case(30, 25, 500, 1000, opts.repeats)
        run_case(200, 100, 500, 1000, opts.repeats)
    print(f"\nload average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
