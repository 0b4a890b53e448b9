"""The test-box examples over several known truths: how often their intervals cover.

The shipped box examples (``box-coheating``, ``box-freefloat``) are one virtual
experiment each, at one truth (``make_box_example.TRUTH``), and the built-in box that is
calibrated is not the EnergyPlus box that made the data (a model-form discrepancy of a
few per cent, docs/case-studies.md). One truth says little about how often the 95 %
intervals hold the truth under that discrepancy. This script repeats the experiment at
``--truths`` truths drawn by a seeded Latin hypercube over the middle 80 % of each prior
(Table 5 of the paper): for each, the data are made as ``make_box_example.py`` makes
them (EnergyPlus at the truth, its own heater sequence or set-point wander and noise,
seed ``SEED + i``; see ``--seed``), the example's study is run with its own settings up
to the predictions, and the script records whether each parameter's 95 % interval covers
its truth and how the bands cover the training and test windows.

It prints a Markdown table per truth and, per parameter, the truths covered against the
binomial bound (the smallest count that 95 % intervals reach with probability 0.99).
``--keep`` keeps the study folders; the table is also written to
``box_truths_<mode>.csv`` in ``--out``, after every truth: a run stopped and started
again with the same ``--truths`` keeps the truths it finished (``--fresh`` redoes them).
``--discrepancy`` replaces the example's in-likelihood discrepancy
(``[outputs.errors.<output>] discrepancy``) to see what it does to the intervals; the
table is then ``box_truths_<mode>_<kind>.csv``. ``--layers`` runs the built-in box with
``window_model = "layers"`` and the Perez sky (the pair nearest EnergyPlus,
tests/simulators/test_energyplus_box.py) instead of the paper's window; its table ends
in ``_layers``. ``--seed`` draws other truths than the default seed's (their data seeded
by ``seed + i``, so seeds less than ``--truths`` apart share noise streams at different
truths); the table ends in ``_seed-<seed>``. ``--sequential`` grows each truth's design
in batches (``[design] sequential = true``, docs/method.md "Sequential design") from a
first hypercube of ``--first`` runs, ``--batch`` runs a batch, up to ``--max-runs`` (by
default 10, 5 and 20: half the paper's 40 runs); the table gets the runs each truth used
and why its design stopped, and ends in ``_sequential``.

Run (each truth is about one minute on the idle 2-core machine)::

    .venv/bin/python scripts/box_truths.py freefloat --truths 10 --out /tmp/boxtruths
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy.stats import binom, qmc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

import make_box_example as box  # noqa: E402

from bayescal.config import load_study  # noqa: E402
from bayescal.examples import copy_example  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402

#: Paper Table 5: the priors of the four parameters (uniform).
PRIORS = {
    "k_wall": (0.05, 0.2),
    "d_wall": (1500.0, 3000.0),
    "r_ag": (0.17, 0.35),
    "t_w": (0.5, 0.72),
}
SEED = 20261127
INNER = 0.8  # truths inside the middle 80 % of each prior


def truths(
    n: int, seed: int = SEED, priors: dict[str, tuple[float, float]] | None = None
) -> list[dict[str, float]]:
    """``n`` truths: a Latin hypercube over the middle ``INNER`` of each prior
    (``priors``: name -> uniform bounds, default the box's :data:`PRIORS`)."""
    bounds = PRIORS if priors is None else priors
    unit = qmc.LatinHypercube(d=len(bounds), seed=seed).random(n)
    unit = 0.5 * (1.0 - INNER) + INNER * unit
    return [
        {k: lo + u * (hi - lo) for u, (k, (lo, hi)) in zip(row, bounds.items(), strict=True)}
        for row in unit
    ]


#: ``--discrepancy`` choices and the TOML value each writes.
DISCREPANCY = {
    "none": "false",
    "conditions": '"conditions"',
    "independent": '"independent"',
    "both": '"both"',
    "orthogonal": '"orthogonal"',
}


def _edit_once(study: Path, pattern: str, replace: str, what: str) -> None:
    """Replace the one match of ``pattern`` (a line) in ``study`` by ``replace``."""
    text, count = re.subn(pattern, replace, study.read_text(encoding="utf-8"), flags=re.M)
    if count != 1:
        raise RuntimeError(f"{study}: expected one {what}, found {count}")
    study.write_text(text, encoding="utf-8")


def set_discrepancy(study: Path, kind: str) -> None:
    """Replace the one ``discrepancy = ...`` line of the example's ``study`` file by
    ``kind`` (a key of :data:`DISCREPANCY`)."""
    line = f"discrepancy = {DISCREPANCY[kind]}"
    _edit_once(study, r"^discrepancy = .*$", line, "'discrepancy = ' line")


#: ``[simulator]`` settings of ``--layers``.
LAYERS = {"window_model": '"layers"', "sky_model": '"perez"'}


def set_simulator(study: Path, settings: dict[str, str]) -> None:
    """Add ``settings`` (key -> TOML value) to the ``[simulator]`` table of ``study``."""
    lines = "".join(f"{k} = {v}\n" for k, v in settings.items())
    _edit_once(study, r"^\[simulator\]\n", "[simulator]\n" + lines, "[simulator] table")


def set_sequential(study: Path, first: int, batch: int, max_runs: int) -> None:
    """Make the ``[design]`` of ``study`` sequential: a first hypercube of ``first``
    runs, batches of ``batch`` runs, at most ``max_runs`` runs in all."""
    _edit_once(
        study,
        r"^(\[design\]\n(?:#.*\n)*)runs = \d+$",
        rf"\g<1>runs = {first}\nsequential = true\nbatch = {batch}\nmax_runs = {max_runs}",
        "[design] runs line",
    )


#: The end of the line a sequential design's stop is said in, by the reason's start.
STOPS = {"the emulator's error": "tolerance", "max_runs": "max_runs", "the shift": "stalled"}


def stop_reason(line: str) -> str:
    """``tolerance``, ``max_runs``, ``stalled`` or ``max_minutes`` from the design's
    ``design: sequential design stopped at N runs (...)`` line."""
    why = line.split("(", 1)[1]
    return next((v for k, v in STOPS.items() if why.startswith(k)), "max_minutes")


def one_truth(
    mode: str,
    index: int,
    values: dict[str, float],
    folder: Path,
    discrepancy: str | None = None,
    simulator: dict[str, str] | None = None,
    sequential: tuple[int, int, int] | None = None,
    noise: str | None = None,
    seed: int = SEED,
) -> dict[str, object]:
    """Make the data at ``values`` (noise and heater sequence or set-point wander seeded
    by ``seed + index``), run the example's study (its in-likelihood discrepancy replaced by
    ``discrepancy``, one of :data:`DISCREPANCY`, if given; its design sequential with
    ``sequential = (first, batch, max_runs)`` if given), score its intervals and bands."""
    name = f"box-{mode}"
    shutil.rmtree(folder, ignore_errors=True)
    copy_example(name, folder)
    if discrepancy is not None:
        set_discrepancy(folder / "study.toml", discrepancy)
    if simulator:
        set_simulator(folder / "study.toml", simulator)
    if sequential:
        set_sequential(folder / "study.toml", *sequential)
    if noise is not None:
        _edit_once(folder / "study.toml", r"^\[predict\]\n", f'[predict]\nnoise = "{noise}"\n',
                   "[predict] table")  # fmt: skip
    table = box.make_phase(mode, np.random.default_rng(seed + index), values)
    table.to_parquet(folder / "data" / f"{name}.parquet", index=False, compression="zstd")
    start = time.perf_counter()
    said: list[str] = []
    res = run(load_study(folder), until="predict", options=Options(), say=said.append)
    seconds = time.perf_counter() - start
    post = res.posterior
    if post is None or res.predictions is None or res.design is None:
        raise RuntimeError(f"truth {index}: the run stopped before its predictions")
    lower, upper = post.interval(0.95)
    mean = post.draws.reshape(-1, len(post.names)).mean(axis=0)
    row: dict[str, object] = {"truth": index, "seconds": round(seconds, 1)}
    row["runs"] = res.design.runs
    if sequential:
        stops = [line for line in said if "sequential design stopped at" in line]
        row["stop"] = stop_reason(stops[-1]) if stops else "unknown"
        row["steps"] = sum(bool(re.match(r"design: \d+ runs \(", line)) for line in said)
    for j, p in enumerate(post.names):
        row[f"{p}_true"] = values[p]
        row[f"{p}_mean"] = float(mean[j])
        row[f"{p}_lower"] = float(lower[j])
        row[f"{p}_upper"] = float(upper[j])
        row[f"{p}_covered"] = bool(lower[j] <= values[p] <= upper[j])
    row["rhat_max"] = float(np.nanmax(post.diagnostics.rhat))
    row["ess_bulk_min"] = float(np.nanmin(post.diagnostics.ess_bulk))
    m = res.predictions.metrics
    for window in ("train", "test"):
        r = m[(m["model"] == "calibrated") & (m["window"] == window)].iloc[0]
        row[f"band95_{window}"] = float(r["coverage95"])
        row[f"band50_{window}"] = float(r["coverage50"])
    return row


def finished(csv: Path, drawn: list[dict[str, float]]) -> list[dict[str, object]]:
    """The rows of an earlier run kept in ``csv``: its first truths, where they are the
    truths drawn now (same count and seed, the same parameters), in order."""
    if not csv.exists():
        return []
    rows: list[dict[str, object]] = []
    for row in pd.read_csv(csv).to_dict("records"):
        i = len(rows)
        same = i < len(drawn) and all(
            np.isclose(float(row[f"{k}_true"]), v, rtol=1e-12) for k, v in drawn[i].items()
        )
        if int(row["truth"]) != i or not same:
            break
        rows.append({str(k): v for k, v in row.items()})
    return rows


def binomial_floor(n: int, rate: float = 0.95, alpha: float = 0.01) -> int:
    """The smallest count of ``n`` intervals at ``rate`` reached with probability ``1 - alpha``."""
    return int(binom.ppf(alpha, n, rate))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=("freefloat", "coheating"))
    parser.add_argument("--truths", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("box_truths"))
    parser.add_argument("--keep", action="store_true", help="keep every truth's study folder")
    parser.add_argument("--fresh", action="store_true", help="redo truths already in the CSV")
    parser.add_argument(
        "--discrepancy",
        choices=tuple(DISCREPANCY),
        help="replace the example's in-likelihood discrepancy (default: the example's own)",
    )
    parser.add_argument(
        "--layers",
        action="store_true",
        help='the built-in box with window_model = "layers" and the Perez sky',
    )
    parser.add_argument(
        "--sequential", action="store_true", help="[design] sequential = true (table: _sequential)"
    )
    parser.add_argument("--first", type=int, default=10, help="--sequential: first design runs")
    parser.add_argument("--batch", type=int, default=5, help="--sequential: runs per batch")
    parser.add_argument("--max-runs", type=int, default=20, help="--sequential: most runs in all")
    parser.add_argument(
        "--noise",
        choices=("simulator", "basis", "calibration"),
        default=None,
        help="[predict] noise of the studies (table: _noise-<value>; default: the example's)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=SEED,
        help=f"seed of the truths' hypercube and of each truth's data (table: _seed-<value>; "
        f"default {SEED}): another seed draws other truths",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    suffix = (
        (f"_{args.discrepancy}" if args.discrepancy else "")
        + ("_layers" if args.layers else "")
        + ("_sequential" if args.sequential else "")
        + (f"_noise-{args.noise}" if args.noise else "")
        + (f"_seed-{args.seed}" if args.seed != SEED else "")
    )
    sequential = (args.first, args.batch, args.max_runs) if args.sequential else None
    csv = args.out / f"box_truths_{args.mode}{suffix}.csv"
    drawn = truths(args.truths, seed=args.seed)
    rows = [] if args.fresh else finished(csv, drawn)
    if rows:
        print(f"{len(rows)} truth(s) already in {csv} kept (--fresh redoes them)")
    for i, values in enumerate(drawn):
        if i < len(rows):
            continue
        folder = args.out / f"{args.mode}{suffix}-{i}"
        rows.append(
            one_truth(
                args.mode,
                i,
                values,
                folder,
                args.discrepancy,
                LAYERS if args.layers else None,
                sequential,
                args.noise,
                args.seed,
            )
        )
        print(f"truth {i}: " + ", ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)
        partial = csv.with_suffix(".csv.part")
        pd.DataFrame(rows).to_csv(partial, index=False)
        partial.replace(csv)  # atomic: a killed run keeps the truths it finished
    table = pd.DataFrame(rows)
    n = len(table)
    floor = binomial_floor(n)
    print(f"\n{args.mode}: {n} truths; 95 % intervals reach {floor} of {n} with probability 0.99")
    print("| parameter | covered | mean (truth - mean) / interval half-width |")
    print("|---|---|---|")
    for p in PRIORS:
        covered = int(table[f"{p}_covered"].sum())
        half = 0.5 * (table[f"{p}_upper"] - table[f"{p}_lower"])
        z = ((table[f"{p}_true"] - table[f"{p}_mean"]) / half).mean()
        flag = "" if covered >= floor else " (below the bound)"
        print(f"| {p} | {covered} / {n}{flag} | {z:+.2f} |")
    for w in ("train", "test"):
        b95, b50 = table[f"band95_{w}"], table[f"band50_{w}"]
        print(
            f"bands, {w}: 95 % {b95.min():.3f}-{b95.max():.3f} (median {b95.median():.3f}), "
            f"50 % {b50.min():.3f}-{b50.max():.3f} (median {b50.median():.3f})"
        )
    print(f"R-hat <= {table['rhat_max'].max():.4f}, bulk ESS >= {table['ess_bulk_min'].min():.0f}")
    if "runs" in table:
        runs = table["runs"]
        print(
            f"runs: {runs.min()}-{runs.max()} (mean {runs.mean():.1f}); seconds per truth: "
            f"{table['seconds'].min():.0f}-{table['seconds'].max():.0f} "
            f"(median {table['seconds'].median():.0f}, total {table['seconds'].sum():.0f})"
        )
    if "stop" in table:
        counts = table["stop"].value_counts()
        print("design stopped by: " + ", ".join(f"{k} {v}" for k, v in counts.items()))


if __name__ == "__main__":
    main()
