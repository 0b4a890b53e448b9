"""The office example at full size: screen, design, calibrate, report; with times and truth.

The numbers of ``docs/case-studies.md`` (section "A whole building") come from
this script. It copies the ``office`` example into ``out/case-studies/office``
(as ``bayescal init office`` does), then runs what a modeller runs:

1. ``bayescal screen --apply``: Sobol indices of a GP fitted to 42 EnergyPlus runs
   over the 21 candidates (``[screening]``); the proposed parameters get
   ``screen = false``;
2. ``bayescal run``: a sequential design whose first runs are the screening's
   (``[design]``), EnergyPlus runs, emulator, calibration, predictions
   (``[predict] method = "auto"``), report;

and prints the screening ranks, the posterior against the hidden truth
(:data:`make_office_example.TRUTH`; the other candidates are at their
nominal values in the data), the Guideline 14 table (hourly and monthly,
training and held-out weeks), the size of the emulator and the time of every
step, as Markdown with ``--markdown``.

Usage::

    OPENBLAS_NUM_THREADS=1 python scripts/office_case_study.py [--fresh] [--jobs N]
        [--backend processes|dask] [--scheduler ADDRESS] [--out DIR] [--markdown]

``--morris`` runs the settings the example shipped with before (Morris screening,
10 trajectories: 220 runs, at most 8 parameters; a one-shot design of 150 runs;
predictions by EnergyPlus at 30 posterior draws): about 400 runs, the baseline of
issue 36. ``--few-runs`` switches to the variants tried on the way (Sobol screening
on 42 runs, fewer design runs); with ``--reuse`` the screening's runs join the design (``[design]
reuse_screening = true``) and, without ``--design-runs``, the new runs are set from the
screening: 10 per calibrated parameter in all, the screening's counted; with
``--reuse --sequential`` the screening's runs and 12 new ones are the first design of a
sequential design (batches of 12, at most 10 runs per calibrated parameter in all:
the shipped settings with ``--max-parameters 9``).

Running it again reuses the cached EnergyPlus runs and every finished stage;
``--fresh`` starts from an empty folder.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import tomli_w

from bayescal.cli.progress import screening_text
from bayescal.config import load_study
from bayescal.examples import copy_example
from bayescal.pipeline import Options, run
from bayescal.pipeline.screen import screen

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

from make_office_example import TRUTH  # noqa: E402


def _markdown(frame: pd.DataFrame, digits: int = 4) -> str:
    def cell(value: object) -> str:
        if isinstance(value, float | np.floating):
            return "–" if not np.isfinite(value) else f"{value:.{digits}g}"
        return str(value)

    head = [str(frame.index.name or "")] + [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for index, row in frame.iterrows():
        lines.append("| " + " | ".join([str(index)] + [cell(v) for v in row]) + " |")
    return "\n".join(lines)


def posterior_vs_truth(study_dir: Path) -> pd.DataFrame:
    """Posterior mean and 95 % interval of each calibrated parameter, with its truth."""
    study = load_study(study_dir)
    summary = pd.read_csv(study.root / study.study.output_dir / "posterior-summary.csv")
    summary = summary.set_index("parameter").loc[list(study.calibrated)]
    nominal = {name: study.parameters[name].nominal for name in study.calibrated}
    truth = {name: TRUTH.get(name, nominal[name]) for name in study.calibrated}
    frame = pd.DataFrame(
        {
            "nominal": pd.Series(nominal),
            "truth": pd.Series(truth),
            "mean": summary["mean"],
            "lower": summary["lower"],
            "upper": summary["upper"],
            "r_hat": summary["r_hat"],
            "ess_bulk": summary["ess_bulk"],
        }
    )
    frame["truth inside"] = np.where(
        (frame["truth"] >= frame["lower"]) & (frame["truth"] <= frame["upper"]), "yes", "no"
    )
    frame.index.name = "parameter"
    return frame


def guideline14(study_dir: Path) -> pd.DataFrame:
    """CV(RMSE), NMBE (hourly and monthly) of the nominal and calibrated models."""
    study = load_study(study_dir)
    metrics = pd.read_csv(study.root / study.study.output_dir / "metrics.csv")
    cols = ["output", "model", "window", "n", "cv_rmse", "nmbe", "guideline14"]
    cols += ["n_months", "cv_rmse_monthly", "nmbe_monthly", "guideline14_monthly"]
    frame = metrics[metrics["model"].isin(["nominal", "calibrated"])][cols]
    return frame.set_index("output")


def _few_runs(
    path: Path,
    max_parameters: int = 8,
    design_runs: int | None = None,
    reuse: bool = False,
    sequential: bool = False,
) -> None:
    """Switch a fresh copy of the office study to the settings of ``--few-runs``
    (``design_runs``: a one-shot design of that many runs instead of the sequential one;
    ``reuse``: a one-shot design after the screening's runs, ``[design] reuse_screening``;
    ``reuse`` and ``sequential``: the screening's runs, then a sequential design)."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    data["screening"] = {
        "method": "sobol",
        "runs": 42,
        "statistic": "mean",
        "threshold": 0.0225,
        "max_parameters": max_parameters,
    }
    data["design"] = (
        {"runs": 24, "sequential": True, "batch": 12, "max_runs": 72}
        if design_runs is None and not reuse
        else {"runs": design_runs or 2 + max_parameters}
    )
    if reuse:
        data["design"]["reuse_screening"] = True
    if reuse and sequential:
        # the screening's 42 runs and 12 new ones first, batches of 12, at most the
        # one-shot reuse design's 10 runs per calibrated parameter (90 for nine)
        data["design"] |= {
            "runs": 12,
            "sequential": True,
            "batch": 12,
            "max_runs": 10 * max_parameters,
        }
    data["predict"] = {**data["predict"], "method": "auto"}
    path.write_text(tomli_w.dumps(data), encoding="utf-8")


def _morris(path: Path) -> None:
    """Switch a fresh copy of the office study to the settings it shipped with before
    issue 36: Morris screening (220 runs), a one-shot design of 150, the simulator route."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    data["screening"] = {
        "trajectories": 10,
        "levels": 4,
        "statistic": "mean",
        "threshold": 0.15,
        "max_parameters": 8,
    }
    data["design"] = {"runs": 150}
    data["predict"] = {**data["predict"], "method": "simulator"}
    path.write_text(tomli_w.dumps(data), encoding="utf-8")


def _reuse_runs(path: Path, screening_runs: int) -> None:
    """Set ``[design] runs`` from the screening: 10 runs per calibrated parameter in all
    (Loeppky et al. 2009's rule for a GP emulator), the screening's hypercube counted
    (it spans the calibrated parameters' ranges too)."""
    t = len(load_study(path.parent).calibrated)
    runs = max(t + 2, 10 * t - screening_runs)
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    data["design"]["runs"] = runs
    path.write_text(tomli_w.dumps(data), encoding="utf-8")
    print(f"design: {runs} new runs = 10 x {t} calibrated parameters - {screening_runs} reused")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "out" / "case-studies" / "office")
    parser.add_argument("--fresh", action="store_true", help="delete earlier results first")
    parser.add_argument("--jobs", type=int, default=None, help="parallel EnergyPlus runs")
    parser.add_argument("--backend", choices=["processes", "dask"], default=None)
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address")
    parser.add_argument("--markdown", action="store_true", help="print Markdown tables")
    parser.add_argument(
        "--morris",
        action="store_true",
        help="the settings shipped before issue 36: Morris screening (220 runs, at most 8 "
        "parameters), a one-shot design of 150 runs, predictions by EnergyPlus at 30 draws",
    )
    parser.add_argument(
        "--few-runs",
        action="store_true",
        help="issue 36's settings: Sobol screening on a Latin hypercube of 2 x 21 runs "
        "(threshold 0.0225 = 0.15 squared), a sequential design (24 first runs, batches of "
        "12, at most 72) and [predict] method = 'auto'",
    )
    parser.add_argument(
        "--max-parameters",
        type=int,
        default=8,
        help="--few-runs: most parameters the screening proposes (8)",
    )
    parser.add_argument(
        "--design-runs",
        type=int,
        default=None,
        help="--few-runs: a one-shot Latin hypercube of this many runs instead of the "
        "sequential design",
    )
    parser.add_argument(
        "--reuse",
        action="store_true",
        help="--few-runs: [design] reuse_screening = true, a one-shot design after the "
        "screening's runs; without --design-runs its new runs are 10 x the calibrated "
        "parameters minus the screening's runs (at least parameters + 2)",
    )
    parser.add_argument(
        "--sequential",
        action="store_true",
        help="--few-runs --reuse: the screening's runs and 12 new ones, then a sequential "
        "design in batches of 12 up to 10 x the calibrated parameters in all",
    )
    args = parser.parse_args(argv)
    if args.sequential and not (args.few_runs and args.reuse and args.design_runs is None):
        parser.error("--sequential needs --few-runs --reuse and no --design-runs")
    if args.morris and args.few_runs:
        parser.error("--morris and --few-runs are two different settings; give one")
    folder: Path = args.out
    if args.fresh and folder.exists():
        shutil.rmtree(folder)
    if (args.morris or args.few_runs) and (folder / "study.toml").is_file():
        print(
            f"{folder / 'study.toml'} exists and keeps its settings: --morris and --few-runs "
            "apply to a fresh copy (add --fresh)"
        )
    if not (folder / "study.toml").is_file():
        copy_example("office", folder)
        if args.morris:
            _morris(folder / "study.toml")
        if args.few_runs:
            _few_runs(
                folder / "study.toml",
                args.max_parameters,
                args.design_runs,
                args.reuse,
                args.sequential,
            )
    options = Options(backend=args.backend, jobs=args.jobs, scheduler=args.scheduler)
    start = time.perf_counter()
    screened = screen(load_study(folder), options=options, apply=True, say=print)
    print(screening_text(screened.indices, screened.proposal))
    print(f"screening: {screened.seconds:.1f} s ({screened.runs.n_run} EnergyPlus runs)")
    if args.few_runs and args.reuse and args.design_runs is None and not args.sequential:
        _reuse_runs(folder / "study.toml", screened.design.runs)
    res = run(load_study(folder), until="report", options=options, say=print)
    total = time.perf_counter() - start
    stages = json.loads((res.context.out / "stages.json").read_text(encoding="utf-8"))
    times = {"screen": screened.seconds} | {k: float(v["seconds"]) for k, v in stages.items()}
    em = res.emulator
    sizes = ""
    if em is not None:
        a = em.assembled
        sizes = (
            f"emulator: R = {a.theta.shape[0]} runs x m* = {a.x.shape[0]} daily periods x "
            f"{len(res.context.study.outputs.calibrate)} outputs x 24 h; p = {a.basis.p} "
            f"basis vectors, {a.x.shape[1]} inputs x, {a.theta.shape[1]} parameters"
        )
    print()
    print(sizes)
    print("times [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in times.items()))
    print(f"end to end (this invocation): {total:.1f} s")
    made = len(list((res.context.out / "simulations" / "runs").glob("*.npz")))
    print(f"EnergyPlus runs in the cache (every run made, the nominal one included): {made}")
    truth = posterior_vs_truth(folder)
    g14 = guideline14(folder)
    if args.markdown:
        print()
        print(_markdown(truth))
        print()
        print(_markdown(g14, digits=3))
        print()
        print(_markdown(pd.DataFrame({"seconds": pd.Series(times)}).rename_axis("step"), 4))
    else:
        print(truth.to_string())
        print(g14.to_string())
    print(f"report: {res.report}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
