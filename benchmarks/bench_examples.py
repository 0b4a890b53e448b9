"""Every worked example end to end: stage times, diagnostics, ESS per second (issue 18).

For each example of ``bayescal init`` (``bayescal.examples.available()``) the
script copies the study into a fresh folder (as ``bayescal init NAME`` does;
the Twin House study is pointed at the shared Annex 58 data as
``scripts/run_case_studies.py`` does, and skipped with a message where they are
missing), runs the whole pipeline (``design`` to ``report``) with the study's
own settings and the default options, and prints one table:

* the wall time of every stage (from ``stages.json``) and in all, and the CPU
  time in all (this process and its worker processes; on a busy machine the
  steadier figure);
* per MCMC phase (``cal``: calibration, ``disc``: the difference process's
  theta* phase, where enabled) the largest R-hat and the smallest bulk and tail
  ESS over every parameter, and the bulk ESS per second of the slowest
  parameter (smallest bulk ESS / the phase's stage time);
* whether the example meets the issue's goal: at most 60 s end to end, every
  R-hat <= 1.01 and every bulk and tail ESS >= 400 in every phase; the
  ``misses`` column says what failed.

The ``office`` example (the DOE small office in EnergyPlus) is listed but not
run unless asked for (``--office``, or by naming it): its study marks every
parameter as a screening candidate, so ``bayescal run`` refuses it until
``bayescal screen --apply`` has chosen the parameters, and the two together are
96 EnergyPlus runs, about 15 minutes on the 2-core machine
(docs/case-studies.md; ``scripts/office_case_study.py`` prints its full
results). Run, it goes the user's way: Sobol screening with ``--apply``
(its time is the ``screen`` column), then the pipeline; its end-to-end time
includes the screening.

BLAS and OpenMP are single-threaded (set before numpy is imported); chains and
simulations use the default backends (worker processes where the defaults say
so). The load average is printed before and after: the goal is stated for the
idle 2-core machine.

Run::

    .venv/bin/python benchmarks/bench_examples.py                 # all but office
    .venv/bin/python benchmarks/bench_examples.py --office        # all, office included
    .venv/bin/python benchmarks/bench_examples.py wall box-freefloat
    .venv/bin/python benchmarks/bench_examples.py --keep DIR      # keep the study folders
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

from run_case_studies import CaseError, prepare_case  # noqa: E402

from bayescal.config import load_study  # noqa: E402
from bayescal.errors import BayescalError  # noqa: E402
from bayescal.examples import available, copy_example  # noqa: E402
from bayescal.mcmc.diagnostics import Diagnostics  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402
from bayescal.pipeline.screen import screen  # noqa: E402

GOAL_SECONDS = 60.0
GOAL_RHAT = 1.01
GOAL_ESS = 400.0
STAGES = (
    "screen",
    "design",
    "simulate",
    "emulator",
    "calibrate",
    "discrepancy",
    "predict",
    "report",
)
SHORT = {"calibrate": "cal", "discrepancy": "disc"}
#: The example that screens before it runs, and why it is not run by default.
OFFICE = "office"
OFFICE_NOT_RUN = (
    "not run: EnergyPlus, screen --apply then run, 96 runs, ~15 min on 2 cores "
    "(docs/case-studies.md); --office runs it, scripts/office_case_study.py gives its results"
)


@dataclass
class Phase:
    """Diagnostics of one MCMC phase."""

    name: str
    seconds: float
    diagnostics: Diagnostics

    @property
    def rhat(self) -> float:
        return float(np.nanmax(self.diagnostics.rhat))

    @property
    def ess_bulk(self) -> float:
        return float(np.nanmin(self.diagnostics.ess_bulk))

    @property
    def ess_tail(self) -> float:
        return float(np.nanmin(self.diagnostics.ess_tail))

    @property
    def slowest(self) -> str:
        return self.diagnostics.names[int(np.nanargmin(self.diagnostics.ess_bulk))]

    @property
    def ess_per_second(self) -> float:
        return self.ess_bulk / self.seconds if self.seconds > 0 else float("nan")

    def misses(self) -> list[str]:
        out = []
        short = SHORT[self.name]
        if not self.rhat <= GOAL_RHAT:
            out.append(f"{short} R-hat {self.rhat:.3f}")
        if not self.ess_bulk >= GOAL_ESS:
            out.append(f"{short} bulk ESS {self.ess_bulk:.0f} ({self.slowest})")
        if not self.ess_tail >= GOAL_ESS:
            out.append(f"{short} tail ESS {self.ess_tail:.0f}")
        return out


@dataclass
class Row:
    """One example's result."""

    name: str
    times: dict[str, float] = field(default_factory=dict)
    total: float = float("nan")
    cpu: float = float("nan")
    phases: list[Phase] = field(default_factory=list)
    error: str = ""
    not_run: str = ""

    def misses(self) -> list[str]:
        if self.not_run:
            return [self.not_run]
        if self.error:
            return [self.error]
        out = [] if self.total <= GOAL_SECONDS else [f"{self.total:.0f} s > {GOAL_SECONDS:.0f} s"]
        for phase in self.phases:
            out.extend(phase.misses())
        return out


def cpu_seconds() -> float:
    """CPU seconds of this process and of its finished worker processes."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def run_example(name: str, parent: Path, until: str) -> Row:
    """Copy, run and diagnose one example (the office one screened first, with --apply)."""
    row = Row(name)
    folder = parent / name
    try:
        if name == OFFICE:  # no preparation, but fresh like the others
            shutil.rmtree(folder, ignore_errors=True)
            copy_example(name, folder)
        else:
            prepare_case(name, folder, fresh=True)
    except CaseError as exc:
        row.error = f"skipped: {exc}"
        return row
    cpu0, start = cpu_seconds(), time.perf_counter()
    screened = None
    try:
        if name == OFFICE:
            screened = screen(load_study(folder), options=Options(), apply=True)
        res = run(load_study(folder), until=until, options=Options())
    except BayescalError as exc:
        row.error = f"failed: {exc.one_line()}"
        return row
    row.total = time.perf_counter() - start
    row.cpu = cpu_seconds() - cpu0
    record = json.loads((res.context.out / "stages.json").read_text(encoding="utf-8"))
    if screened is not None:
        row.times["screen"] = screened.seconds
    row.times |= {stage: float(entry["seconds"]) for stage, entry in record.items()}
    if res.posterior is not None:
        row.phases.append(
            Phase("calibrate", row.times.get("calibrate", 0.0), res.posterior.diagnostics)
        )
    if res.discrepancy is not None:
        row.phases.append(
            Phase(
                "discrepancy",
                row.times.get("discrepancy", 0.0),
                res.discrepancy.posterior.diagnostics,
            )
        )
    return row


def print_table(rows: list[Row]) -> None:
    """The examples table (stage times in seconds)."""
    stage_cols = [s for s in STAGES if any(s in r.times for r in rows)]
    head = [f"{'example':14s}"] + [f"{s[:8]:>8s}" for s in stage_cols]
    head += [f"{'total':>7s}", f"{'CPU':>7s}"]
    head += [
        f"{'phase':>5s}",
        f"{'max R-hat':>9s}",
        f"{'min bulk':>8s}",
        f"{'min tail':>8s}",
        f"{'ESS/s':>7s}",
        "  goal",
    ]
    print(" ".join(head))
    for r in rows:
        if r.not_run or r.error:
            print(f"{r.name:14s} {r.not_run or r.error}")
            continue
        cells = [f"{r.name:14s}"] + [f"{r.times.get(s, float('nan')):8.1f}" for s in stage_cols]
        cells += [f"{r.total:7.1f}", f"{r.cpu:7.1f}"]
        misses = r.misses()
        verdict = "  met" if not misses else "  MISSED: " + "; ".join(misses)
        phases = r.phases or [None]
        for k, phase in enumerate(phases):
            lead = cells if k == 0 else [" " * len(c) for c in cells]
            if phase is None:
                tail = [f"{'-':>5s}", f"{'':>9s}", f"{'':>8s}", f"{'':>8s}", f"{'':>7s}"]
            else:
                tail = [
                    f"{SHORT[phase.name]:>5s}",
                    f"{phase.rhat:9.4f}",
                    f"{phase.ess_bulk:8.0f}",
                    f"{phase.ess_tail:8.0f}",
                    f"{phase.ess_per_second:7.1f}",
                ]
            print(" ".join(lead + tail) + (verdict if k == 0 else ""))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "examples",
        nargs="*",
        help="examples to run (default: all; office listed, not run, without --office)",
    )
    parser.add_argument("--keep", type=Path, help="folder for the study folders (kept)")
    parser.add_argument("--until", default="report", choices=["predict", "report"])
    parser.add_argument(
        "--office",
        action="store_true",
        help="also run the office example (EnergyPlus: screen --apply, then run; ~15 min)",
    )
    opts = parser.parse_args()
    names = list(opts.examples or available())
    unknown = sorted(set(names) - set(available()))
    if unknown:
        parser.error(f"unknown examples {unknown}; choose from {available()}")
    if opts.office and OFFICE not in names:
        names.append(OFFICE)
    # named on the command line, or asked for with --office: run; else listed as not run
    run_office = opts.office or OFFICE in opts.examples
    print(
        f"examples end to end ({', '.join(names)}); BLAS threads 1, {os.cpu_count()} CPUs, "
        f"load average at start {os.getloadavg()[0]:.1f}; goal: <= {GOAL_SECONDS:.0f} s, "
        f"R-hat <= {GOAL_RHAT}, bulk and tail ESS >= {GOAL_ESS:.0f} in every phase"
    )
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="bayescal-examples-") as tmp:
        parent = opts.keep if opts.keep is not None else Path(tmp)
        parent.mkdir(parents=True, exist_ok=True)
        for name in names:
            if name == OFFICE and not run_office:
                rows.append(Row(name, not_run=OFFICE_NOT_RUN))
                print(f"  {name}: {OFFICE_NOT_RUN}", flush=True)
                continue
            rows.append(run_example(name, parent, opts.until))
            row = rows[-1]
            print(f"  {name}: {row.error or f'{row.total:.1f} s'}", flush=True)
    print()
    print_table(rows)
    print(f"\nload average at end {os.getloadavg()[0]:.1f} (times are wall times)")
    return 1 if any(r.error.startswith("failed") for r in rows) else 0


if __name__ == "__main__":
    raise SystemExit(main())
