"""EnergyPlus at scale: the runner on the office example, serial, processes x 2 and Dask x 2.

The simulator is the ``office`` example's (the DOE reference small office,
9 March - 13 April hourly, 2 warm-up days: a 38-day EnergyPlus run at 6 time
steps per hour, with design-day sizing), all 21 parameters free, at
``--runs`` points of a Latin hypercube over their priors (at least 23: a design
needs two runs more than parameters); every configuration starts from an empty
cache. Printed:

* runs per second overall (worker start-up included) and in steady state
  (between the first and the last finished run), and the parallel efficiency
  ``rate(2 workers) / (2 rate(serial))``;
* where one run's time goes: EnergyPlus's own run time (``Elapsed Time`` in
  ``eplusout.err``), the rest of ``simulate()`` (model copy and JSON, the
  child Python process and the library load, reading ``eplusout.sql``), and
  the runner's share (dispatch, pickling, the atomic cache write), from
  the serial configuration;
* what a run leaves on disk: the cached result (``runs/<key>.npz``) against
  the run folder EnergyPlus writes, with the adapter's requested series only
  and with the reference model's own reports (its 36 ``Output*`` objects).

Run as ``python benchmarks/bench_energyplus.py [--runs N]`` from the repository
root (it sets ``OPENBLAS_NUM_THREADS=1`` itself; the numbers and the time it
takes are in docs/benchmarks.md, "EnergyPlus at scale").
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import json
import re
import shutil
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.atomic import read_npz
from bayescal.config import build_simulator, study_from_dict
from bayescal.config.energyplus import package_file
from bayescal.data import load_measured
from bayescal.design import latin_hypercube
from bayescal.examples import path as example_path
from bayescal.runner import run_design
from bayescal.simulators.energyplus_model import load_model
from bayescal.simulators.energyplus_run import run_energyplus

_ELAPSED = re.compile(r"Elapsed Time=(\d+)hr\s+(\d+)min\s+([\d.]+)sec")


def _study(out: Path, keep: bool) -> Any:
    folder = example_path("office")
    raw = tomllib.loads((folder / "study.toml").read_text(encoding="utf-8"))
    raw["study"]["output_dir"] = str(out)
    raw["simulator"]["keep_outputs"] = keep
    return study_from_dict(raw, root=folder)


def _elapsed(err: Path) -> float:
    found = _ELAPSED.search(err.read_text(encoding="utf-8", errors="replace"))
    if found is None:
        return float("nan")
    h, m, s = found.groups()
    return 3600.0 * int(h) + 60.0 * int(m) + float(s)


def _size(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def _measure(study: Any, runs: int, cache: Path, **options: Any) -> dict[str, float]:
    simulator = build_simulator(study, screening=True)
    forcing = load_measured(study).forcing
    design = latin_hypercube(study.screening_priors(), runs, seed=0)
    stamps: list[float] = []

    def progress(done: int, failed: int, total: int) -> None:
        if done + failed > 0:
            stamps.append(time.perf_counter())

    start = time.perf_counter()
    results = run_design(simulator, forcing, design, cache_dir=cache, progress=progress, **options)
    elapsed = time.perf_counter() - start
    if results.n_failed:
        raise RuntimeError(f"{results.n_failed} runs failed: {results.failures[0].message}")
    seconds = [
        json.loads(str(read_npz(p)["metadata"]))["seconds"] for p in (cache / "runs").glob("*.npz")
    ]
    return {
        "overall": runs / elapsed,
        "steady": (len(stamps) - 1) / (stamps[-1] - stamps[0]),
        "first": stamps[0] - start,
        "elapsed": elapsed,
        "simulate": float(np.median(seconds)),
        "npz": float(np.median([p.stat().st_size for p in (cache / "runs").glob("*.npz")])),
    }


def _reference_reports(work: Path) -> tuple[float, int, float, int]:
    """E+ time and folder size of one run with the adapter's outputs, and with the model's own."""
    kept = sorted((work / "energyplus").glob("bayescal-eplus-*"))[0]
    model = json.loads((kept / "model.epJSON").read_text(encoding="utf-8"))
    reference = load_model(package_file("pyenergyplus:model/RefBldgSmallOfficeNew2004_Chicago.idf"))
    reports = {
        k: v for k, v in reference.items() if k.startswith("Output") and k != "Output:SQLite"
    }
    model.update(reports)
    model["Output:SQLite"] = {"Output:SQLite 1": {"option_type": "SimpleAndTabular"}}
    full = work / "full"
    full.mkdir()
    (full / "model.epJSON").write_text(json.dumps(model), encoding="utf-8")
    shutil.copy(kept / "weather.epw", full / "weather.epw")
    run_energyplus(["-w", "weather.epw", "-d", "out", "model.epJSON"], timeout=600.0, cwd=full)
    return (
        _elapsed(kept / "out" / "eplusout.err"),
        _size(kept),
        _elapsed(full / "out" / "eplusout.err"),
        _size(full),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=24, help="runs per configuration (>= 23)")
    args = parser.parse_args()
    from distributed import LocalCluster

    load = os.getloadavg()[0]
    print(f"cores: {len(os.sched_getaffinity(0))}, load average before: {load:.1f}")
    start = time.perf_counter()
    cluster = LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    )
    print(f"Dask LocalCluster(2 workers) start-up: {time.perf_counter() - start:.2f} s")
    configs: dict[str, dict[str, Any]] = {
        "serial": {"backend": "serial"},
        "processes x2": {"backend": "processes", "jobs": 2},
        "dask x2": {"backend": "dask", "scheduler": cluster.scheduler_address},
    }
    timings: dict[str, dict[str, float]] = {}
    energyplus: dict[str, float] = {}
    with cluster, tempfile.TemporaryDirectory() as tmp:
        for label, options in configs.items():
            work = Path(tmp) / label.replace(" ", "")
            study = _study(work, keep=True)
            timings[label] = _measure(study, args.runs, work / "cache", **options)
            errs = sorted((work / "energyplus").glob("bayescal-eplus-*/out/eplusout.err"))
            energyplus[label] = float(np.median([_elapsed(e) for e in errs]))
        adapter_time, adapter_size, full_time, full_size = _reference_reports(Path(tmp) / "serial")
    print(f"\noffice, {args.runs} runs: runs/s overall | steady state | first result [s]")
    for label, t in timings.items():
        print(f"  {label:<13} {t['overall']:6.3f} | {t['steady']:6.3f} | {t['first']:6.2f}")
    serial = timings["serial"]
    for label in ("processes x2", "dask x2"):
        overall = timings[label]["overall"] / (2 * serial["overall"])
        steady = timings[label]["steady"] / (2 * serial["steady"])
        print(f"  parallel efficiency {label}: {overall:.2f} overall, {steady:.2f} steady")
    per_run = serial["elapsed"] / args.runs
    own = energyplus["serial"]
    print("\none run (serial, medians):")
    print(f"  EnergyPlus's own run time (eplusout.err):  {own:6.2f} s")
    print(f"  simulate() in all:                         {serial['simulate']:6.2f} s")
    print(f"    of which the adapter (files, child process, sql): {serial['simulate'] - own:.2f} s")
    print(f"  runner's share (wall per run - simulate):  {per_run - serial['simulate']:6.2f} s")
    print(
        f"  EnergyPlus's run time under 2 workers: {energyplus['processes x2']:.2f} s (processes), "
        f"{energyplus['dask x2']:.2f} s (Dask)"
    )
    print("\non disk per run:")
    print(f"  cached result (runs/<key>.npz): {serial['npz'] / 1e3:8.1f} kB")
    print(
        f"  run folder, requested series only: {adapter_size / 1e6:6.2f} MB ({adapter_time:.2f} s)"
    )
    print(
        f"  run folder with the reference model's own reports: {full_size / 1e6:6.2f} MB "
        f"({full_time:.2f} s)"
    )


if __name__ == "__main__":
    main()
