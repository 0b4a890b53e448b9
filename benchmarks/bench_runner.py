"""Runs per second of :func:`bayescal.runner.run_design`, serial against 2 workers.

Three simulators:

* ``trivial`` - microseconds per run: measures the runner's own overhead
  (worker start-up, messages, the atomic cache write of every run);
* ``busy``   - a fixed amount of CPU work per run (about 0.1 s): measures the
  parallel efficiency ``rate(2 workers) / (2 * rate(serial))``;
* ``wall``   - the built-in :class:`~bayescal.simulators.wall.MultilayerWall`
  over a year of half-hourly boundary conditions;
* ``energyplus wall`` - the paper's wall in EnergyPlus (conduction transfer
  functions, one process per run) over 20 days, if EnergyPlus is installed.

Every configuration starts from an empty cache, so times include starting
the worker processes (the Dask ``LocalCluster`` is started once beforehand:
its start-up is printed separately). Run as
``python benchmarks/bench_runner.py [--scale F]`` (it sets
``OPENBLAS_NUM_THREADS=1`` itself). "steady state" is the rate between the
first and the last finished run, i.e. without the worker start-up.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import importlib.util
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from bayescal.design import UniformPrior, latin_hypercube
from bayescal.runner import run_design
from bayescal.simulators.base import Forcing


@dataclass(frozen=True)
class Trivial:
    """``y = a * temp_air_out + b``: no work at all."""

    parameter_names: ClassVar[tuple[str, ...]] = ("a", "b")
    input_names: ClassVar[tuple[str, ...]] = ("temp_air_out",)
    output_names: ClassVar[tuple[str, ...]] = ("y",)

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        return {"y": parameters["a"] * forcing["temp_air_out"] + parameters["b"]}


@dataclass(frozen=True)
class Busy(Trivial):
    """The same output after ``sweeps`` passes of elementwise work (CPU-bound, no BLAS)."""

    sweeps: int = 100

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        x = np.linspace(0.0, 1.0, 100_000) * parameters["a"]
        for _ in range(self.sweeps):
            x = np.sin(x) + 0.5 * x
        out = super().simulate(parameters, forcing)
        out["y"] = out["y"] + 0.0 * x[: forcing.n].sum()
        return out


def _forcing(n: int) -> Forcing:
    hours = np.arange(n) / 2.0
    return Forcing(1800.0, {"temp_air_out": 10.0 + 5.0 * np.sin(2 * np.pi * hours / 24.0)})


@dataclass(frozen=True)
class Case:
    """A simulator, its boundary conditions and the priors of its design."""

    name: str
    simulator: Any
    forcing: Forcing
    priors: dict[str, UniformPrior]
    runs: int  # runs per measurement at --scale 1


@dataclass(frozen=True)
class Timing:
    """One measurement: overall and steady-state rates, and the start-up delay."""

    overall: float  # runs / wall time of the whole call [1/s]
    steady: float  # runs / time between the first and the last finished run [1/s]
    first: float  # time to the first finished run (worker start-up included) [s]


def _measure(case: Case, runs: int, **options: Any) -> Timing:
    sim, forcing, priors = case.simulator, case.forcing, case.priors
    design = latin_hypercube(priors, runs, seed=0)
    stamps: list[float] = []

    def progress(done: int, failed: int, total: int) -> None:
        if done + failed > 0:
            stamps.append(time.perf_counter())

    with tempfile.TemporaryDirectory() as cache:
        start = time.perf_counter()
        results = run_design(sim, forcing, design, cache_dir=cache, progress=progress, **options)
        elapsed = time.perf_counter() - start
    if results.n_run != runs:
        raise RuntimeError(f"{results.n_failed} runs failed: {results.failures[:1]}")
    steady = (len(stamps) - 1) / (stamps[-1] - stamps[0])
    return Timing(runs / elapsed, steady, stamps[0] - start)


AB = {"a": UniformPrior(0.5, 1.5), "b": UniformPrior(-1.0, 1.0)}


def _energyplus() -> Case | None:
    """The paper's wall in EnergyPlus (CTF), 20 days half-hourly, if EnergyPlus is installed."""
    if importlib.util.find_spec("pyenergyplus") is None:
        return None
    from bayescal.simulators.energyplus import paper_wall_simulator

    n = 960
    hours = np.arange(n) / 2.0
    series = {
        "temp_surf_out": 2.0 + 6.0 * np.sin(2 * np.pi * hours / 24.0),
        "temp_surf_in": 21.0 + 0.3 * np.sin(2 * np.pi * hours / 3.0),
    }
    forcing = Forcing(1800.0, series, np.datetime64("2013-01-15T00:00"))
    priors = {"k_cb": UniformPrior(0.08, 0.16), "cp_cb": UniformPrior(640.0, 960.0)}
    return Case("energyplus wall", paper_wall_simulator(), forcing, priors, 12)


def _wall() -> Case | None:
    try:
        from bayescal.simulators.fvm import Layer
        from bayescal.simulators.wall import MultilayerWall
    except ImportError:
        return None
    layers = [
        Layer("render", 0.02, 0.8, 1800.0, 900.0),
        Layer("concrete", 0.2, 1.6, 2300.0, 880.0),
        Layer("insulation", 0.08, 0.035, 30.0, 1400.0),
    ]
    wall = MultilayerWall(
        layers,
        parameters={"k_concrete": "concrete.conductivity", "k_ins": "insulation.conductivity"},
        boundary="air",
    )
    n = 17_520  # one year, half-hourly
    hours = np.arange(n) / 2.0
    series = {
        "temp_air_out": 5.0 + 8.0 * np.sin(2 * np.pi * hours / 24.0),
        "temp_air_in": np.full(n, 20.0),
    }
    priors = {"k_concrete": UniformPrior(1.2, 2.0), "k_ins": UniformPrior(0.03, 0.045)}
    return Case("wall", wall, Forcing(1800.0, series), priors, 200)


def main() -> None:
    import bench_runner as me  # workers must import the simulators from a module, not __main__

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, default=1.0, help="multiplies the run counts")
    args = parser.parse_args()
    cases = [
        Case("trivial", me.Trivial(), _forcing(1_500), AB, 200),
        Case("busy", me.Busy(), _forcing(1_500), AB, 40),
    ]
    cases += [case for case in (_wall(), _energyplus()) if case is not None]

    from distributed import LocalCluster

    start = time.perf_counter()
    cluster = LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    )
    print(f"Dask LocalCluster(2 workers) start-up: {time.perf_counter() - start:.2f} s")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"cores: {len(os.sched_getaffinity(0))}, load average before: {load:.1f}")
    configs: dict[str, dict[str, Any]] = {
        "serial": {"backend": "serial"},
        "processes x1": {"backend": "processes", "jobs": 1},
        "processes x2": {"backend": "processes", "jobs": 2},
        "dask x2": {"backend": "dask", "scheduler": cluster.scheduler_address},
    }
    with cluster:
        for case in cases:
            runs = max(5, round(case.runs * args.scale))
            print(f"\n{case.name} ({runs} runs): runs/s overall | steady state | first result [s]")
            timings = {label: _measure(case, runs, **opts) for label, opts in configs.items()}
            for label, t in timings.items():
                print(f"  {label:<13} {t.overall:9.1f} | {t.steady:9.1f} | {t.first:6.2f}")
            serial = timings["serial"]
            for label in ("processes x2", "dask x2"):
                overall = timings[label].overall / (2 * serial.overall)
                steady = timings[label].steady / (2 * serial.steady)
                print(f"  parallel efficiency {label}: {overall:.2f} overall, {steady:.2f} steady")
    if hasattr(os, "getloadavg"):
        print(f"\nload average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
