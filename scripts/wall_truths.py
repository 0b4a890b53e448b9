"""The wall example over several known truths: how often its intervals cover, and with
how many runs.

The shipped ``wall`` example is one virtual experiment at one truth
(``make_wall_example.TRUTH``): EnergyPlus's wall (conduction transfer functions) makes
the data, the built-in finite-volume wall is calibrated on a one-shot design of
``[design] runs = 30``. This script repeats the experiment at ``--truths`` truths drawn
by a seeded Latin hypercube over the middle 80 % of each prior (the paper's Table 2): for
each, the data are made as ``make_wall_example.py`` makes them (boundary temperatures from
the Chicago weather, the inside surface's own seeded wander, the ``--truth`` model's flux
at the truth plus noise of variance 0.007 (W/m²)², seed ``SEED + i``), the example's
study is run with its own settings up to the predictions, and the script records whether
each parameter's 95 % interval covers its truth, how the bands cover the training and
test windows, the largest R-hat and smallest bulk ESS, the seconds of the run and the
runs its design used.

It prints a Markdown table and, per parameter, the truths covered against the binomial
bound (the smallest count that 95 % intervals reach with probability 0.99: 7 of 10), and
the mean of |truth - mean| over the interval's half-width (about 0.41 for honest normal
intervals). ``--runs N`` replaces the example's ``[design] runs``; ``--sequential``
grows each truth's design in batches instead (``[design] sequential = true``,
docs/method.md "Sequential design") from a first hypercube of ``--first`` runs,
``--batch`` runs a batch, up to ``--max-runs`` (by default 7, 4 and 15: at most half the
example's 30 runs), and the table gets why each design stopped. ``--truth builtin``
makes the data with the built-in wall instead of EnergyPlus (no model-form difference at
all). ``--keep`` keeps the study folders; the table is written to
``wall_truths[_<variant>].csv`` in ``--out`` after every truth: a run stopped and
started again with the same ``--truths`` keeps the truths it finished (``--fresh``
redoes them).

Run (a truth takes 15-30 s on the 2-core machine, a sequential one about twice that)::

    .venv/bin/python scripts/wall_truths.py --truths 10 --out /tmp/walltruths
    .venv/bin/python scripts/wall_truths.py --truths 10 --runs 15 --out /tmp/walltruths
    .venv/bin/python scripts/wall_truths.py --truths 10 --sequential --out /tmp/walltruths
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

sys.path.insert(0, str(Path(__file__).resolve().parent))

import make_wall_example as wall  # noqa: E402
from box_truths import binomial_floor, finished, set_sequential, stop_reason  # noqa: E402
from box_truths import truths as box_truths  # noqa: E402

from bayescal.config import load_study  # noqa: E402
from bayescal.examples import copy_example  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402

#: The paper's Table 2: the priors of the three parameters (uniform), as the example's.
PRIORS = {
    "k_cb": (0.08, 0.16),
    "cp_cb": (640.0, 960.0),
    "cp_fb": (672.0, 1008.0),
}
SEED = 20261129


def truths(n: int, seed: int = SEED) -> list[dict[str, float]]:
    """``n`` truths: a Latin hypercube over the middle 80 % of each prior (as the box's)."""
    return box_truths(n, seed, PRIORS)


def set_runs(study: Path, runs: int) -> None:
    """Replace the one ``runs = N`` line of the ``[design]`` table of ``study`` by ``runs``."""
    text, count = re.subn(
        r"^(\[design\]\n(?:#.*\n)*)runs = \d+$",
        rf"\g<1>runs = {runs}",
        study.read_text(encoding="utf-8"),
        flags=re.M,
    )
    if count != 1:
        raise RuntimeError(f"{study}: expected one [design] runs line, found {count}")
    study.write_text(text, encoding="utf-8")


def one_truth(
    index: int,
    values: dict[str, float],
    folder: Path,
    truth: str = "energyplus",
    runs: int | None = None,
    sequential: tuple[int, int, int] | None = None,
) -> dict[str, object]:
    """Make the data at ``values`` with the ``truth`` model, run the example's study (its
    ``[design] runs`` replaced by ``runs`` if given; its design sequential with
    ``sequential = (first, batch, max_runs)`` if given), score its intervals and bands."""
    shutil.rmtree(folder, ignore_errors=True)
    copy_example("wall", folder)
    if runs is not None:
        set_runs(folder / "study.toml", runs)
    if sequential:
        set_sequential(folder / "study.toml", *sequential)
    start = time.perf_counter()
    table = wall.make_data(np.random.default_rng(SEED + index), truth, values)
    wall.write_data(table, folder / "data" / "wall.csv")
    data_seconds = time.perf_counter() - start
    start = time.perf_counter()
    said: list[str] = []
    res = run(load_study(folder), until="predict", options=Options(), say=said.append)
    seconds = time.perf_counter() - start
    post = res.posterior
    if post is None or res.predictions is None or res.design is None:
        raise RuntimeError(f"truth {index}: the run stopped before its predictions")
    lower, upper = post.interval(0.95)
    mean = post.draws.reshape(-1, len(post.names)).mean(axis=0)
    row: dict[str, object] = {
        "truth": index,
        "seconds": round(seconds, 1),
        "data_seconds": round(data_seconds, 1),
        "runs": res.design.runs,
    }
    if sequential:
        stops = [line for line in said if "sequential design stopped at" in line]
        row["stop"] = stop_reason(stops[-1]) if stops else "unknown"
        row["steps"] = sum(bool(re.match(r"design: \d+ runs \(", line)) for line in said)
        history = folder / "out" / "sequential" / "history.csv"
        shifts = pd.read_csv(history)["shift"].dropna() if history.exists() else pd.Series()
        row["shift_last"] = float(shifts.iloc[-1]) if len(shifts) else float("nan")
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
        row[f"mse_{window}"] = float(r["mse"]) if "mse" in r else float("nan")
    return row


def summary(table: pd.DataFrame, title: str) -> None:
    """Print the per-truth table, the coverage per parameter against the binomial bound,
    the bands, the diagnostics, the runs and the seconds."""
    n = len(table)
    floor = binomial_floor(n)
    print(f"\n{title}: {n} truths; 95 % intervals reach {floor} of {n} with probability 0.99")
    print("\n| truth | runs | " + " | ".join(PRIORS) + " | 95 % / 50 % band, train | test "
          "| R-hat max | bulk ESS min | seconds |")  # fmt: skip
    print("|---" * (len(PRIORS) + 7) + "|")
    for _, r in table.iterrows():
        cells = [
            f"{r[f'{p}_true']:.5g} [{r[f'{p}_lower']:.5g}, {r[f'{p}_upper']:.5g}]"
            + ("" if r[f"{p}_covered"] else " **miss**")
            for p in PRIORS
        ]
        print(
            f"| {int(r['truth'])} | {int(r['runs'])} | " + " | ".join(cells)
            + f" | {r['band95_train']:.3f} / {r['band50_train']:.3f}"
            f" | {r['band95_test']:.3f} / {r['band50_test']:.3f}"
            f" | {r['rhat_max']:.4f} | {r['ess_bulk_min']:.0f} | {r['seconds']:.1f} |"
        )  # fmt: skip
    print("\n| parameter | covered | z = (truth - mean) / interval half-width: mean, "
          "mean of abs(z) | median interval width / prior width |")  # fmt: skip
    print("|---|---|---|---|")
    for p, (lo, hi) in PRIORS.items():
        covered = int(table[f"{p}_covered"].sum())
        half = 0.5 * (table[f"{p}_upper"] - table[f"{p}_lower"])
        z = (table[f"{p}_true"] - table[f"{p}_mean"]) / half
        width = (2.0 * half / (hi - lo)).median()
        flag = "" if covered >= floor else " (below the bound)"
        zs = f"{z.mean():+.2f}, {z.abs().mean():.2f}"
        print(f"| {p} | {covered} / {n}{flag} | {zs} | {width:.4f} |")
    for w in ("train", "test"):
        b95, b50 = table[f"band95_{w}"], table[f"band50_{w}"]
        print(
            f"bands, {w}: 95 % {b95.min():.3f}-{b95.max():.3f} (median {b95.median():.3f}), "
            f"50 % {b50.min():.3f}-{b50.max():.3f} (median {b50.median():.3f})"
        )
    print(f"R-hat <= {table['rhat_max'].max():.4f}, bulk ESS >= {table['ess_bulk_min'].min():.0f}")
    runs = table["runs"]
    print(
        f"runs: {runs.min()}-{runs.max()} (mean {runs.mean():.1f}); seconds per truth: "
        f"{table['seconds'].min():.0f}-{table['seconds'].max():.0f} "
        f"(median {table['seconds'].median():.0f}, total {table['seconds'].sum():.0f}; "
        f"data {table['data_seconds'].median():.1f} s a truth, median)"
    )
    if "stop" in table:
        counts = table["stop"].value_counts()
        print("design stopped by: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
        shift = table["shift_last"]
        print(
            f"last shift (posterior SD): {shift.min():.3g}-{shift.max():.3g} "
            f"(median {shift.median():.3g})"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("wall_truths"))
    parser.add_argument("--keep", action="store_true", help="keep every truth's study folder")
    parser.add_argument("--fresh", action="store_true", help="redo truths already in the CSV")
    parser.add_argument(
        "--truth",
        choices=("energyplus", "builtin"),
        default="energyplus",
        help="the model that makes the data (default, as the example's: EnergyPlus)",
    )
    parser.add_argument(
        "--runs", type=int, default=None, help="[design] runs (table: _runs-N; default 30)"
    )
    parser.add_argument(
        "--sequential", action="store_true", help="[design] sequential = true (table: _sequential)"
    )
    parser.add_argument("--first", type=int, default=7, help="--sequential: first design runs")
    parser.add_argument("--batch", type=int, default=4, help="--sequential: runs per batch")
    parser.add_argument("--max-runs", type=int, default=15, help="--sequential: most runs in all")
    args = parser.parse_args()
    if args.sequential and args.runs is not None:
        parser.error("--runs and --sequential: give the first design with --first")
    args.out.mkdir(parents=True, exist_ok=True)
    suffix = (
        (f"_{args.truth}" if args.truth != "energyplus" else "")
        + (f"_runs-{args.runs}" if args.runs is not None else "")
        + (f"_sequential-{args.first}-{args.batch}-{args.max_runs}" if args.sequential else "")
    )
    sequential = (args.first, args.batch, args.max_runs) if args.sequential else None
    csv = args.out / f"wall_truths{suffix}.csv"
    drawn = truths(args.truths)
    rows = [] if args.fresh else finished(csv, drawn)
    if rows:
        print(f"{len(rows)} truth(s) already in {csv} kept (--fresh redoes them)")
    for i, values in enumerate(drawn):
        if i < len(rows):
            continue
        folder = args.out / f"wall{suffix}-{i}"
        rows.append(one_truth(i, values, folder, args.truth, args.runs, sequential))
        print(f"truth {i}: " + ", ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)
        partial = csv.with_suffix(".csv.part")
        pd.DataFrame(rows).to_csv(partial, index=False)
        partial.replace(csv)  # atomic: a killed run keeps the truths it finished
    summary(pd.DataFrame(rows), f"wall{suffix or ' (shipped)'}")


if __name__ == "__main__":
    main()
