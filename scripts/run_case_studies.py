"""Run a shipped case study at full size and print its posterior and metrics.

The results quoted in ``docs/case-studies.md`` come from this script. Each case
is a worked example of ``bayescal.examples``, copied (as ``bayescal init``
does) into an output folder and run by the pipeline with the example's own
settings; the script then prints the posterior table, the diagnostics, the
train/test metrics of the nominal and calibrated models, the time of every
stage and, with ``--markdown``, the same tables as Markdown.

Cases:

``wall``
    The paper's wall (virtual experiment shipped with the example).
``box-coheating``, ``box-freefloat``
    The paper's test box (virtual experiments shipped with the examples).
``twinhouse``
    The Annex 58 Twin House N2 west façade. Its measurements are not in the
    repository: the script looks for
    ``../shared/data/annex58-twinhouse-n2-exp1/validationdataN2Exp1.txt``
    beside the repository root and points the copied study at it.

Usage::

    OPENBLAS_NUM_THREADS=1 python scripts/run_case_studies.py twinhouse [--markdown]
        [--out DIR] [--fresh] [--until predict|report] [--jobs N] [--serial]

The output folder defaults to ``out/case-studies/NAME`` under the repository
root (ignored by git). Running again reuses every finished stage (``--fresh``
starts from scratch).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from bayescal.cli.progress import describe
from bayescal.config import load_study
from bayescal.errors import BayescalError
from bayescal.examples import copy_example
from bayescal.pipeline import Options, Results, run

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"
TWINHOUSE_FILE = SHARED_DATA / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"
TWINHOUSE_DATA_LINE = 'file = "data/validationdataN2Exp1.txt"'


class CaseError(Exception):
    """A case study cannot be prepared (missing data, changed example)."""


def _prepare_wall(folder: Path) -> None:
    """The paper's wall ships its (virtual) data: nothing to do."""


def _prepare_twinhouse(folder: Path) -> None:
    """Point the copied Twin House study at the shared Annex 58 data."""
    if not TWINHOUSE_FILE.is_file():
        raise CaseError(
            f"the Twin House measurements are not at {TWINHOUSE_FILE} (the shared data "
            f"folder is expected beside the repository root {REPO}); get "
            "validationdataN2Exp1.txt as src/bayescal/examples/twinhouse/README.md says "
            "and put it there"
        )
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    if text.count(TWINHOUSE_DATA_LINE) != 1:
        raise CaseError(f"{path} has no line {TWINHOUSE_DATA_LINE!r} to point at the data")
    text = text.replace(TWINHOUSE_DATA_LINE, f"file = {TWINHOUSE_FILE.as_posix()!r}")
    path.write_text(text, encoding="utf-8")


CASES: dict[str, Callable[[Path], None]] = {
    "wall": _prepare_wall,
    "box-coheating": _prepare_wall,  # the test box ships its (virtual) data too
    "box-freefloat": _prepare_wall,
    "twinhouse": _prepare_twinhouse,
}


def prepare_case(name: str, folder: Path, *, fresh: bool = False) -> Path:
    """Copy the example ``name`` into ``folder`` and make it runnable here."""
    if fresh and folder.exists():
        shutil.rmtree(folder)
    copy_example(name, folder, force=True)
    CASES[name](folder)
    return folder


def _markdown(frame: pd.DataFrame, digits: int = 4) -> str:
    """A pandas frame as a Markdown table (values with ``digits`` significant digits)."""

    def cell(value: object) -> str:
        if isinstance(value, float):
            return f"{value:.{digits}g}"
        return str(value)

    head = [str(frame.index.name or "")] + [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for index, row in frame.iterrows():
        lines.append("| " + " | ".join([str(index)] + [cell(v) for v in row]) + " |")
    return "\n".join(lines)


def markdown_tables(res: Results) -> str:
    """Posterior and metrics tables of a finished run, in Markdown."""
    parts: list[str] = []
    if res.posterior is not None:
        table = res.posterior.summary()
        cols = ["mean", "sd", "lower", "upper", "r_hat", "ess_bulk", "ess_tail"]
        parts.append(_markdown(table[cols]))
    if res.predictions is not None:
        m = res.predictions.metrics.set_index("output")
        cols = ["model", "window", "rmse", "mean_abs_error", "max_abs_error", "bias"]
        cols += ["cv_rmse", "nmbe", "coverage95"]
        parts.append(_markdown(m[[c for c in cols if c in m.columns]]))
    return "\n\n".join(parts)


def stage_times(out: Path) -> dict[str, float]:
    """Seconds spent in every stage recorded in ``out/stages.json``."""
    record = json.loads((out / "stages.json").read_text(encoding="utf-8"))
    return {stage: float(entry["seconds"]) for stage, entry in record.items()}


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("case", choices=sorted(CASES))
    parser.add_argument("--out", type=Path, help="study folder (default out/case-studies/CASE)")
    parser.add_argument("--fresh", action="store_true", help="delete earlier results first")
    parser.add_argument("--until", default="predict", choices=["predict", "report"])
    parser.add_argument("--jobs", type=int, help="parallel simulation workers")
    parser.add_argument("--serial", action="store_true", help="no worker processes at all")
    parser.add_argument("--markdown", action="store_true", help="also print Markdown tables")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Run one case study; return the exit status."""
    args = _parse(argv)
    folder = args.out or REPO / "out" / "case-studies" / args.case
    try:
        prepare_case(args.case, folder, fresh=args.fresh)
        options = Options(
            backend="serial" if args.serial else None,
            jobs=args.jobs,
            chains_backend="serial" if args.serial else "processes",
        )
        start = time.perf_counter()
        res = run(load_study(folder), until=args.until, options=options, say=print)
        elapsed = time.perf_counter() - start
    except (BayescalError, CaseError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print()
    print(describe(res))
    times = stage_times(res.context.out)
    print()
    print("stage times [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in times.items()))
    print(f"this invocation: {elapsed:.1f} s (stages reused: {', '.join(res.reused) or 'none'})")
    if args.markdown:
        print()
        print(markdown_tables(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
