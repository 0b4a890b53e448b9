"""NUTS (JAX/BlackJAX) against Metropolis-within-Gibbs for theta* on the virtual wall.

The calibration posterior (eq. 16) of the virtual wall of ``tests/helpers/virtual_wall.py``
at the paper's size (R = 30 runs x m* = 25 daily periods, basis at 99 % of the
variance, emulator trained as in tests/calibration/test_calibration.py). Per repeat, and
interleaved so that both samplers see the same machine load:

* MwG: :func:`bayescal.calibration.posterior.calibrate` at the default lengths
  (4 chains, 2000 burn-in + 5000 kept sweeps, ``backend="serial"``);
* NUTS: :func:`bayescal.calibration.hmc.sample_nuts_isolated` (what
  ``calibrate(..., sampler="nuts")`` runs: NUTS in a spawned process) with 500
  warm-up + 1000 kept iterations, 4 chains one after another, then the same
  ArviZ diagnostics;
* with ``--variants`` also MwG with 2 worker processes (``backend="processes"``,
  calibrate's default) and NUTS with the 4 chains vmapped into one program.

Reported per run: wall and CPU seconds (``time.process_time`` of this process
plus ``getrusage(RUSAGE_CHILDREN)`` of the waited-for worker processes: on a
shared machine the CPU time is the steadier measure), JIT compile time of NUTS, the
bulk ESS of each theta* and its minimum, the largest R-hat, and ESS per second
including and excluding the compile time; at the end the medians over repeats
and the ratio NUTS / MwG. Everything is single-threaded (set before numpy and
JAX are imported)::

    .venv/bin/python benchmarks/bench_hmc.py               # 3 repeats, ~2-4 min idle
    .venv/bin/python benchmarks/bench_hmc.py --quick       # short chains, 1 repeat
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "")
    + " --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
).strip()

import argparse  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from bayescal.calibration import hmc  # noqa: E402
from bayescal.calibration.kron import make_algebra  # noqa: E402
from bayescal.calibration.posterior import calibrate  # noqa: E402
from bayescal.calibration.target import LAMBDA_NAMES, CalibrationPosterior, default_starts  # noqa: E402
from bayescal.emulator.assemble import Assembled, assemble  # noqa: E402
from bayescal.emulator.gp import Emulator  # noqa: E402
from bayescal.emulator.training import train  # noqa: E402
from bayescal.mcmc.diagnostics import diagnose  # noqa: E402
from virtual_wall import virtual_experiment  # noqa: E402


def children_cpu_seconds() -> float:
    """CPU time [s] of the waited-for child processes (the isolated NUTS run)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@dataclass(frozen=True)
class Run:
    """One sampler run: times [s] and diagnostics of theta*."""

    sampler: str
    wall: float
    cpu: float
    compile_wall: float
    compile_cpu: float
    ess: np.ndarray
    rhat: float
    note: str
    startup_wall: float = 0.0  # NUTS: worker start-up, imports, pickling, diagnostics
    startup_cpu: float = 0.0

    def ess_per_s(self, cpu: bool, with_compile: bool, with_startup: bool = True) -> float:
        seconds = self.cpu if cpu else self.wall
        if not with_compile:
            seconds -= self.compile_cpu if cpu else self.compile_wall
        if not with_startup:
            seconds -= self.startup_cpu if cpu else self.startup_wall
        return float(self.ess.min() / seconds)


def _problem() -> tuple[Emulator, Assembled]:
    ve = virtual_experiment(seed=0)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, variance=0.99)
    return train(a, n_burn=400, n_draws=100, n_chains=1, seed=1), a


def run_mwg(
    em: Emulator, a: Assembled, burn: int, draws: int, seed: int, backend: str = "serial"
) -> Run:
    """calibrate() with its default sampler (chains serial, or 2 worker processes)."""
    wall, cpu, child = time.perf_counter(), time.process_time(), children_cpu_seconds()
    post = calibrate(
        em,
        a,
        n_chains=4,
        n_burn=burn,
        n_draws=draws,
        seed=seed,
        backend=backend,  # type: ignore[arg-type]
    )
    wall = time.perf_counter() - wall
    cpu = time.process_time() - cpu + children_cpu_seconds() - child
    t = len(post.names)
    d = post.diagnostics
    acc = post.acceptance[:, :t].mean()
    name = "mwg" if backend == "serial" else "mwg-processes"
    return Run(name, wall, cpu, 0.0, 0.0, d.ess_bulk[:t], float(d.rhat.max()), f"acc {acc:.2f}")


def run_nuts(
    em: Emulator, a: Assembled, burn: int, draws: int, seed: int, vectorised: bool = False
) -> Run:
    """What calibrate(..., sampler="nuts") runs: sample_nuts in a spawned process."""
    wall, cpu, child = time.perf_counter(), time.process_time(), children_cpu_seconds()
    alg = make_algebra("kronecker", em.theta, em.x, em.kernels, em.basis.ktk, em.w, a.w_star)
    target = CalibrationPosterior(alg, list(a.priors.values()), em.lam_prior, a.lam_star_prior)
    starts = default_starts(target, 4, seed)
    res = hmc.sample_nuts_isolated(target, starts, burn, draws, seed, vectorised=vectorised)
    t = target.t
    phys = np.stack([p.from_unit(res.draws[..., k]) for k, p in enumerate(a.priors.values())], -1)
    everything = np.concatenate([phys, res.draws[..., t:]], axis=-1)
    acc = np.repeat(res.chains.acceptance[:, None], t + 2, 1)
    d = diagnose(everything, (*a.parameter_names, *LAMBDA_NAMES), acc)
    wall = time.perf_counter() - wall
    cpu = time.process_time() - cpu + children_cpu_seconds() - child
    ch = res.chains
    note = (
        f"acc {ch.acceptance.mean():.2f}, {ch.steps.mean():.1f} leapfrog steps/draw, "
        f"{int(ch.divergent.sum())} divergent; in the child: {ch.seconds:.2f} s wall / "
        f"{ch.cpu_seconds:.2f} s CPU, of which sampling {ch.seconds - ch.compile_seconds:.2f}"
        f" / {ch.cpu_seconds - ch.compile_cpu_seconds:.2f} s; process start-up, import and "
        f"diagnostics {wall - ch.seconds:.2f} s wall"
    )
    name = "nuts-vmap" if vectorised else "nuts"
    return Run(
        name,
        wall,
        cpu,
        ch.compile_seconds,
        ch.compile_cpu_seconds,
        d.ess_bulk[:t],
        float(d.rhat.max()),
        note,
        startup_wall=wall - ch.seconds,
        startup_cpu=cpu - ch.cpu_seconds,
    )


def _show(run: Run, names: tuple[str, ...]) -> None:
    ess = ", ".join(f"{n} {e:.0f}" for n, e in zip(names, run.ess, strict=True))
    print(
        f"  {run.sampler:4s}: wall {run.wall:6.2f} s, CPU {run.cpu:6.2f} s "
        f"(compile {run.compile_wall:.2f} s wall / {run.compile_cpu:.2f} s CPU); "
        f"bulk ESS {ess}; max R-hat {run.rhat:.4f}; {run.note}"
    )
    print(
        f"        min ESS/s: CPU {run.ess_per_s(True, True):6.0f} incl. compile, "
        f"{run.ess_per_s(True, False):6.0f} excl.; wall {run.ess_per_s(False, True):6.0f} "
        f"incl., {run.ess_per_s(False, False):6.0f} excl."
    )
    if run.startup_wall:
        print(
            "        sampling only (no compile, no start-up): CPU "
            f"{run.ess_per_s(True, False, False):6.0f}, "
            f"wall {run.ess_per_s(False, False, False):6.0f}"
        )


def _summary(runs: list[Run]) -> None:
    print("\nmedians over repeats (min bulk ESS of theta* per second):")
    medians: dict[tuple[str, bool, bool], float] = {}
    for sampler in dict.fromkeys(r.sampler for r in runs):
        mine = [r for r in runs if r.sampler == sampler]
        for cpu in (True, False):
            for comp in (True, False):
                medians[sampler, cpu, comp] = statistics.median(
                    r.ess_per_s(cpu, comp) for r in mine
                )
        print(
            f"  {sampler}: CPU {medians[sampler, True, True]:.0f} incl. compile / "
            f"{medians[sampler, True, False]:.0f} excl.; wall {medians[sampler, False, True]:.0f}"
            f" / {medians[sampler, False, False]:.0f}; median min ESS "
            f"{statistics.median(float(r.ess.min()) for r in mine):.0f}"
        )
        if mine[0].startup_wall:
            cpu_s = statistics.median(r.ess_per_s(True, False, False) for r in mine)
            wall_s = statistics.median(r.ess_per_s(False, False, False) for r in mine)
            print(f"    sampling only: CPU {cpu_s:.0f}, wall {wall_s:.0f}")
    for cpu in (True, False):
        for comp in (True, False):
            if ("nuts", cpu, comp) not in medians or ("mwg", cpu, comp) not in medians:
                continue
            ratio = medians["nuts", cpu, comp] / medians["mwg", cpu, comp]
            label = f"{'CPU' if cpu else 'wall'} time, {'incl.' if comp else 'excl.'} compile"
            print(f"  ratio NUTS / MwG ({label}): {ratio:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short chains, one repeat")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument(
        "--variants",
        action="store_true",
        help="also MwG with 2 worker processes (calibrate's default backend) and vmapped NUTS",
    )
    opts = parser.parse_args()
    mwg_len, nuts_len = ((200, 500), (150, 250)) if opts.quick else ((2000, 5000), (500, 1000))
    repeats = opts.repeats or (1 if opts.quick else 3)
    print(f"load average before: {os.getloadavg()}")
    start = time.perf_counter()
    em, a = _problem()
    diagnose(np.random.default_rng(0).normal(size=(4, 100, 1)), ["warm-up"])  # import ArviZ
    print(
        f"virtual wall 30 x 25, p = {a.basis.p}: built and trained in "
        f"{time.perf_counter() - start:.1f} s"
    )
    print(
        f"MwG 4 chains x ({mwg_len[0]} + {mwg_len[1]}); NUTS 4 chains x "
        f"({nuts_len[0]} + {nuts_len[1]}); {repeats} repeat(s), interleaved"
    )
    runs = []
    for rep in range(repeats):
        print(f"repeat {rep} (seed {rep + 3})")
        jobs: list[tuple[Any, tuple[int, int], dict[str, Any]]] = [
            (run_mwg, mwg_len, {}),
            (run_nuts, nuts_len, {}),
        ]
        if opts.variants:
            jobs += [(run_mwg, mwg_len, {"backend": "processes"})]
            jobs += [(run_nuts, nuts_len, {"vectorised": True})]
        for fn, lengths, kw in jobs if rep % 2 == 0 else jobs[::-1]:
            runs.append(fn(em, a, *lengths, seed=rep + 3, **kw))
            _show(runs[-1], a.parameter_names)
    _summary(runs)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
