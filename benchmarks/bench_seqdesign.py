"""Runs-to-posterior curves: one-shot designs of increasing size against a sequential one.

For the built-in wall example and the co-heating test box (``bayescal init wall``,
``bayescal init box-coheating``: their shipped data, at their known truths), the
script calibrates

* one-shot Latin hypercubes of increasing size (wall: 8, 15, 30, 60 runs; box: 10,
  20, 40, 80), each in a fresh folder with the example's own settings otherwise;
* one sequential design (``[design] sequential = true``, docs/method.md "Sequential
  design"; wall: a first design of 8 runs, batches of 6, at most 30; box: 10 runs,
  batches of 5, at most 40). Its ``sequential/history.csv`` gives the short
  calibration of each step (the quick posteriors the loop steers by), and the
  pipeline's full calibration on the final design is run too.

It prints one table per example (as soon as that example is done, the figure
redrawn): per design the runs, the wall time, and per parameter the posterior
mean, its distance from the reference mean in reference SDs, and the 95 % interval
width relative to the reference (the largest one-shot design, calibrated in the
same run of this script). The quick steps of the
sequential design give a mean and SD only: their width is 3.92 SD (marked ``~``).
The figure (``--figure``; default ``bayescal-seqdesign.png`` in the temporary
folder) shows mean ± 2 SD against the number of runs for both, with the truth.

BLAS and OpenMP are single-threaded (set before numpy is imported).

Run::

    .venv/bin/python benchmarks/bench_seqdesign.py                        # wall and box
    .venv/bin/python benchmarks/bench_seqdesign.py --quick                # wall only, 8-30 runs
    .venv/bin/python benchmarks/bench_seqdesign.py --figure docs/img/seqdesign.png
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import re  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

import make_box_example  # noqa: E402
import make_wall_example  # noqa: E402

from bayescal.config import load_study  # noqa: E402
from bayescal.examples import copy_example  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402
from bayescal.pipeline.seqdesign import HISTORY_FILE  # noqa: E402

Z95 = 1.959964


@dataclass(frozen=True)
class Case:
    """One example: its one-shot sizes, its sequential settings and its truth."""

    example: str
    sizes: tuple[int, ...]
    first: int
    batch: int
    max_runs: int
    truth: dict[str, float]


CASES = {
    "wall": Case("wall", (8, 15, 30, 60), 8, 6, 30, make_wall_example.TRUTH),
    "box-coheating": Case("box-coheating", (10, 20, 40, 80), 10, 5, 40, make_box_example.TRUTH),
}
QUICK_SIZES = {"wall": (8, 15, 30)}


@dataclass
class Point:
    """One posterior: the design that made it and its summary per parameter."""

    label: str
    runs: int
    seconds: float
    mean: dict[str, float]
    sd: dict[str, float]
    width: dict[str, float]  # 95 % interval width
    approx: bool = False  # width from 3.92 SD (a quick step of the sequential design)


def set_design(study: Path, runs: int, sequential: tuple[int, int] | None = None) -> None:
    """Set ``[design] runs`` of ``study``; ``sequential = (batch, max_runs)`` makes it
    sequential with that first design."""
    extra = ""
    if sequential is not None:
        extra = f"\nsequential = true\nbatch = {sequential[0]}\nmax_runs = {sequential[1]}"
    text, count = re.subn(
        r"^(\[design\]\n(?:#.*\n)*)runs = \d+$",
        rf"\g<1>runs = {runs}{extra}",
        study.read_text(encoding="utf-8"),
        flags=re.M,
    )
    if count != 1:
        raise RuntimeError(f"{study}: no '[design] runs = ' line")
    study.write_text(text, encoding="utf-8")


def cpu_seconds() -> float:
    """CPU seconds of this process and of its finished worker processes."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def calibrate(
    case: Case, folder: Path, runs: int, sequential: bool, say: list[str]
) -> tuple[Point, Path]:
    """Copy the example to ``folder``, set its design, run it up to the calibration."""
    copy_example(case.example, folder)
    set_design(folder / "study.toml", runs, (case.batch, case.max_runs) if sequential else None)
    start = time.perf_counter()
    res = run(load_study(folder), until="calibrate", options=Options(), say=say.append)
    seconds = time.perf_counter() - start
    post, design = res.posterior, res.design
    if post is None or design is None:
        raise RuntimeError(f"{folder}: no posterior")
    flat = post.draws.reshape(-1, len(post.names))
    lower, upper = post.interval(0.95)
    names = post.names
    label = "sequential, full" if sequential else "one-shot"
    point = Point(
        label,
        design.runs,
        seconds,
        dict(zip(names, flat.mean(axis=0).tolist(), strict=True)),
        dict(zip(names, flat.std(axis=0).tolist(), strict=True)),
        dict(zip(names, (upper - lower).tolist(), strict=True)),
    )
    return point, res.context.out


def history_points(out: Path, names: list[str]) -> list[Point]:
    """The quick posteriors of the sequential design's steps (steps without one left out)."""
    table = pd.read_csv(out / HISTORY_FILE)
    points = []
    for _, row in table.iterrows():
        mean = {n: float(row[f"mean_{n}"]) for n in names}
        if not all(np.isfinite(list(mean.values()))):
            continue
        sd = {n: float(row[f"sd_{n}"]) for n in names}
        width = {n: 2 * Z95 * s for n, s in sd.items()}
        points.append(Point("sequential, step", int(row["runs"]), 0.0, mean, sd, width, True))
    return points


def bench(case: Case, parent: Path, sizes: tuple[int, ...]) -> tuple[list[Point], list[Point]]:
    """One-shot points and sequential points (steps, then the full calibration)."""
    one_shot = []
    for n in sizes:
        point, _ = calibrate(case, parent / f"{case.example}-{n}", n, False, [])
        one_shot.append(point)
        print(f"  {case.example}: one-shot {n} runs, {point.seconds:.1f} s", flush=True)
    said: list[str] = []
    final, out = calibrate(case, parent / f"{case.example}-seq", case.first, True, said)
    for line in said:
        if line.startswith("design: "):
            print(f"    {line}", flush=True)
    seq = [*history_points(out, list(final.mean)), final]
    print(f"  {case.example}: sequential, {final.runs} runs, {final.seconds:.1f} s", flush=True)
    return one_shot, seq


def print_table(case: Case, one_shot: list[Point], seq: list[Point]) -> None:
    """Runs, seconds and per parameter: mean, (mean - ref) / ref SD, width / ref width."""
    ref = one_shot[-1]
    names = list(ref.mean)
    print(
        f"\n{case.example}: reference = one-shot {ref.runs} runs (this run); truth "
        + ", ".join(f"{n} {case.truth[n]:.4g}" for n in names)
    )
    head = "| design | runs | seconds | " + " | ".join(
        f"{n}: mean, Δ/SD_ref, width/ref" for n in names
    )
    print(head + " |")
    print("|---|---|---|" + "---|" * len(names))
    for p in [*one_shot, *seq]:
        cells = []
        for n in names:
            shift = (p.mean[n] - ref.mean[n]) / ref.sd[n]
            ratio = p.width[n] / ref.width[n]
            cells.append(f"{p.mean[n]:.4g}, {shift:+.2f}, {'~' if p.approx else ''}{ratio:.2f}")
        secs = f"{p.seconds:.1f}" if p.seconds else "-"
        print(f"| {p.label} | {p.runs} | {secs} | " + " | ".join(cells) + " |")


def figure(results: dict[str, tuple[Case, list[Point], list[Point]]], path: Path) -> None:
    """Mean ± 2 SD against runs, one row per example, one panel per parameter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(results)
    cols = max(len(one[0].mean) for _, one, _ in results.values())
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.8 * rows), squeeze=False)
    for i, (name, (case, one, seq)) in enumerate(results.items()):
        names = list(one[0].mean)
        for j in range(cols):
            ax = axes[i][j]
            if j >= len(names):
                ax.axis("off")
                continue
            n = names[j]
            for pts, style, label, dx in (
                (one, "o-", "one-shot", 0.97),
                ([p for p in seq if p.approx], "s--", "sequential (quick, per step)", 1.0),
                ([p for p in seq if not p.approx], "D", "sequential (full, final)", 1.03),
            ):
                if not pts:
                    continue
                x = np.array([p.runs for p in pts], dtype=float) * dx
                y = np.array([p.mean[n] for p in pts])
                e = 2 * np.array([p.sd[n] for p in pts])
                ax.errorbar(x, y, yerr=e, fmt=style, capsize=3, ms=4, label=label)
            ax.axhline(case.truth[n], color="k", lw=0.8, ls=":", label="truth")
            ax.set_title(f"{name}: {n}", fontsize=9)
            ax.set_xscale("log")
            ax.set_xticks(sorted({p.runs for p in [*one, *seq]}))
            ax.set_xticklabels([str(r) for r in sorted({p.runs for p in [*one, *seq]})])
            ax.minorticks_off()
            ax.set_xlabel("simulator runs", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=6)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"figure: {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("examples", nargs="*", help=f"of {', '.join(CASES)} (default: both)")
    parser.add_argument("--quick", action="store_true", help="the wall only, 8, 15, 30 runs")
    parser.add_argument(
        "--figure", type=Path, default=Path(tempfile.gettempdir()) / "bayescal-seqdesign.png"
    )
    parser.add_argument("--keep", type=Path, help="folder for the study folders (kept)")
    opts = parser.parse_args()
    names = list(opts.examples) or (list(QUICK_SIZES) if opts.quick else list(CASES))
    if unknown := sorted(set(names) - set(CASES)):
        parser.error(f"unknown examples {unknown}; choose from {list(CASES)}")
    print(
        f"runs to posterior ({', '.join(names)}); BLAS threads 1, {os.cpu_count()} CPUs, "
        f"load average at start {os.getloadavg()[0]:.1f}",
        flush=True,
    )
    start, cpu0 = time.perf_counter(), cpu_seconds()
    results = {}
    with tempfile.TemporaryDirectory(prefix="bayescal-seqdesign-") as tmp:
        parent = opts.keep if opts.keep is not None else Path(tmp)
        parent.mkdir(parents=True, exist_ok=True)
        for name in names:
            case = CASES[name]
            sizes = QUICK_SIZES.get(name, case.sizes) if opts.quick else case.sizes
            one, seq = bench(case, parent, sizes)
            results[name] = (case, one, seq)
            print_table(case, one, seq)  # each example's table as soon as it is done
            figure(results, opts.figure)
    print(
        f"{time.perf_counter() - start:.0f} s in all (CPU {cpu_seconds() - cpu0:.0f} s, "
        "this process and its workers); load average at end "
        f"{os.getloadavg()[0]:.1f} (times are wall times)"
    )


if __name__ == "__main__":
    main()
