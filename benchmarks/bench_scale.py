"""Emulator training and calibration at scale: wall time and peak memory (issue 7).

Target of the issue: R = 500 runs x m* = 200 periods x p = 5 bases, emulator
trained and theta* calibrated (4 chains, 5000 sweeps after burn-in) within 15
minutes on 2 cores and under 4 GiB.

Data: the virtual wall of ``tests/helpers/virtual_wall.py`` (the paper's wall driven by
synthetic surface temperatures, "measured" = truth + noise) with ``R`` Latin-
hypercube runs over ``m*`` daily periods, and an output basis of exactly ``p``
components (``assemble(..., components=p)``). Chains run in worker processes
(``backend="processes"``, 2 at a time on 2 cores), BLAS single-threaded.

Training runs the project's default sweeps (``[emulator]`` burn and samples,
read from ``bayescal.config``, 2 chains) unless ``--train-sweeps`` asks for
fewer; the script then prints the measured time and a linear extrapolation to
the default (the cost per sweep does not depend on the number of sweeps; the
MAP refinement and the conditioning are counted once, as measured).
Calibration runs the full 4 x (burn + 5000) sweeps by default.

Peak memory: ``ru_maxrss`` of this process and the largest of its worker
processes (``RUSAGE_CHILDREN``); with 2 workers alive at once the total is at
most this process + 2 x the largest worker, printed as the bound.

Run::

    /usr/bin/time -v .venv/bin/python benchmarks/bench_scale.py --loo   # the issue's size
    .venv/bin/python benchmarks/bench_scale.py --quick         # CI size (~1 minute)
    .venv/bin/python benchmarks/bench_scale.py --train-sweeps 100 100 --loo
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from bayescal.calibration.posterior import calibrate  # noqa: E402
from bayescal.config import EmulatorSection  # noqa: E402
from bayescal.emulator.assemble import assemble  # noqa: E402
from bayescal.emulator.training import train  # noqa: E402
from virtual_wall import virtual_experiment  # noqa: E402

_EMULATOR_DEFAULTS = EmulatorSection()
# [emulator] burn, samples; 2 chains (what the pipeline runs)
DEFAULT_TRAIN = (_EMULATOR_DEFAULTS.burn, _EMULATOR_DEFAULTS.samples, 2)
TARGET_SECONDS = 15 * 60.0
TARGET_BYTES = 4 * 2**30


@dataclass
class Clock:
    """Wall time of the last sampler iteration seen by the progress callback."""

    total: int
    start: float = 0.0
    sampling_done: float = 0.0

    def __call__(self, done: int) -> None:
        if done >= self.total and not self.sampling_done:
            self.sampling_done = time.perf_counter()


@dataclass(frozen=True)
class Cpu:
    """CPU seconds (user + system) of this process and of its finished workers."""

    own: float
    workers: float

    @classmethod
    def now(cls) -> Cpu:
        me = resource.getrusage(resource.RUSAGE_SELF)
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        return cls(me.ru_utime + me.ru_stime, kids.ru_utime + kids.ru_stime)

    def since(self, before: Cpu) -> Cpu:
        return Cpu(self.own - before.own, self.workers - before.workers)

    def idle_wall(self, cores: int) -> float:
        """Wall time on an otherwise idle machine: workers spread over the cores. [s]"""
        return self.own + self.workers / cores

    def text(self, cores: int) -> str:
        return (
            f"CPU {self.own:.0f} s here + {self.workers:.0f} s in workers "
            f"-> {self.idle_wall(cores):.0f} s on {cores} idle cores"
        )


def peak_rss() -> tuple[float, float]:
    """Peak resident memory of this process and of its largest child. [GiB]"""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024.0
    return own / 2**30, child / 2**30


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=500)
    parser.add_argument("--periods", type=int, default=200)
    parser.add_argument("--bases", type=int, default=5)
    parser.add_argument(
        "--train-sweeps",
        type=int,
        nargs=2,
        default=DEFAULT_TRAIN[:2],
        metavar=("BURN", "DRAWS"),
    )
    parser.add_argument("--train-chains", type=int, default=2)
    parser.add_argument("--no-refine", action="store_true", help="skip the L-BFGS-B MAP step")
    parser.add_argument(
        "--cal-sweeps", type=int, nargs=2, default=(2000, 5000), metavar=("BURN", "DRAWS")
    )
    parser.add_argument("--backend", choices=("processes", "serial"), default="processes")
    parser.add_argument("--loo", action="store_true", help="also time leave-one-run-out CV")
    parser.add_argument("--quick", action="store_true", help="CI size: 60 x 30 x 3, short chains")
    opts = parser.parse_args()
    if opts.quick:
        opts.runs, opts.periods, opts.bases = 60, 30, 3
        opts.train_sweeps, opts.cal_sweeps = (50, 50), (200, 300)

    print(
        f"R = {opts.runs} runs x m* = {opts.periods} periods x p = {opts.bases} bases; "
        f"chains backend {opts.backend}, BLAS threads 1, {os.cpu_count()} CPUs; "
        f"load average at start {os.getloadavg()[0]:.1f}"
    )
    start = time.perf_counter()
    ve = virtual_experiment(seed=0, runs=opts.runs, periods=opts.periods)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=opts.bases)
    t_data = time.perf_counter() - start
    print(
        f"  virtual wall simulations + assemble: {t_data:.1f} s (not counted below); "
        f"t = {a.theta.shape[1]}, s = {a.x.shape[1]}, "
        f"{a.n_runs * a.n_periods} weight rows per basis"
    )

    burn, draws = opts.train_sweeps
    n_tr = opts.train_chains
    clock = Clock(n_tr * (burn + draws))
    cores = 1 if opts.backend == "serial" else 2
    cpu0 = Cpu.now()
    start = clock.start = time.perf_counter()
    em = train(
        a,
        n_burn=burn,
        n_draws=draws,
        n_chains=n_tr,
        seed=1,
        backend=opts.backend,
        refine=not opts.no_refine,
        callback=clock,
    )
    t_train = time.perf_counter() - start
    cpu_train = Cpu.now().since(cpu0)
    t_mcmc = (clock.sampling_done or time.perf_counter()) - start
    t_rest = t_train - t_mcmc
    per_sweep = t_mcmc / (burn + draws)  # wall per sweep, chains side by side
    print(
        f"  emulator training: {n_tr} chains x ({burn} + {draws}) sweeps of "
        f"{em.layout.d} coordinates: {t_train:.1f} s "
        f"(MCMC {t_mcmc:.1f} s = {per_sweep:.3f} s per sweep of all chains; "
        f"MAP refinement + conditioning {t_rest:.1f} s)"
    )
    print(f"    {cpu_train.text(cores)}")
    d_burn, d_draws, d_chains = DEFAULT_TRAIN
    # Linear in chain-sweeps at the same parallelism (run with --train-chains 2);
    # the MAP refinement and the conditioning (in this process) are counted once.
    scale = d_chains * (d_burn + d_draws) / (n_tr * (burn + draws))
    t_train_default = t_mcmc * scale + t_rest
    idle_train = cpu_train.workers / cores * scale + cpu_train.own
    print(
        f"  extrapolated to the default training ({d_chains} chains x ({d_burn} + "
        f"{d_draws}) sweeps): {t_train_default / 60:.1f} min at this load, "
        f"{idle_train / 60:.1f} min on {cores} idle cores (linear in sweeps)"
    )

    if opts.loo:
        start = time.perf_counter()
        loo = em.loo_cv()
        rmse = ", ".join(f"{n} {v:.3g}" for n, v in loo.rmse.items())
        print(f"  leave-one-run-out CV: {time.perf_counter() - start:.1f} s (RMSE {rmse})")

    c_burn, c_draws = opts.cal_sweeps
    cpu0 = Cpu.now()
    start = time.perf_counter()
    post = calibrate(
        em, a, n_chains=4, n_burn=c_burn, n_draws=c_draws, seed=3, backend=opts.backend
    )
    t_cal = time.perf_counter() - start
    cpu_cal = Cpu.now().since(cpu0)
    sweeps = 4 * (c_burn + c_draws)
    ess = post.diagnostics.ess_bulk[: len(post.names)]
    print(
        f"  calibration: 4 chains x ({c_burn} + {c_draws}) sweeps: {t_cal:.1f} s "
        f"({1e3 * t_cal / sweeps:.2f} ms per sweep over all chains, wall); "
        f"smallest bulk ESS of theta* {ess.min():.0f}; {len(post.warnings)} warnings"
    )
    print(f"    {cpu_cal.text(cores)}")
    cal_scale = 4 * (c_burn + 5000) / sweeps
    full_cal, idle_cal = t_cal * cal_scale, cpu_cal.idle_wall(cores) * cal_scale
    if c_draws != 5000:
        print(f"  calibration extrapolated to 5000 kept sweeps: {full_cal:.0f} s (linear)")

    own, child = peak_rss()
    bound = own + (2 if opts.backend == "processes" else 0) * child
    print(
        f"  peak RSS: this process {own:.2f} GiB, largest worker {child:.2f} GiB; "
        f"total at most {bound:.2f} GiB (target < {TARGET_BYTES / 2**30:.0f} GiB)"
    )
    measured = t_train + t_cal
    idle = cpu_train.idle_wall(cores) + cpu_cal.idle_wall(cores)
    print(
        f"  train + calibrate as run: {measured / 60:.1f} min wall at this load, "
        f"{idle / 60:.1f} min on {cores} idle cores (from CPU time)"
    )
    print(
        f"  with the default training and 5000 kept sweeps: {(t_train_default + full_cal) / 60:.1f}"
        f" min at this load, {(idle_train + idle_cal) / 60:.1f} min on {cores} idle cores "
        f"(target {TARGET_SECONDS / 60:.0f} min)"
    )
    print(f"  load average at end {os.getloadavg()[0]:.1f} (other jobs share the cores)")
    mean = post.draws.reshape(-1, len(post.names)).mean(axis=0)
    truth = np.array([ve.truth[n] for n in post.names])
    print(
        "  posterior mean / truth: "
        + ", ".join(f"{n} {m:.4g}/{t:.4g}" for n, m, t in zip(post.names, mean, truth, strict=True))
    )


if __name__ == "__main__":
    main()
