"""The test box calibrated on co-heating predicts its free-float phase: do the bands hold?

For ``--truths`` truths (those of ``box_truths.py``: a seeded Latin hypercube over
the middle 80 % of each prior), the data of both phases are made by EnergyPlus at
the truth (``make_box_example.make_phase``, seed ``SEED + i``), the ``box-coheating``
example is calibrated on its phase (its own settings; ``--discrepancy`` replaces its
in-likelihood discrepancy), and ``bayescal predict --as`` predicts the free-float
phase's inside air temperature with that posterior (the ``box-freefloat`` study with
the sensor's accuracy stated: ``sd = 0.1`` K, the noise the data were made with).
The free-float record was seen by no calibration. The band of the free-float
temperature holds the parameters' uncertainty and the stated accuracy; the
co-heating discrepancy (on the heating power) does not carry over to another output.

With ``--sequential`` the free-float study is calibrated instead, with the
co-heating posterior as its prior (``[study] prior_from``), and the row holds whether
each parameter's 95 % interval covers its truth after both phases, and the free-float
test window's bands.

Prints a row per truth and the coverage over the truths; writes
``box_transfer[_<kind>].csv`` into ``--out`` after every truth (a run started again
keeps the truths it finished).

Run (each truth is about one to three minutes on the idle 2-core machine)::

    .venv/bin/python scripts/box_transfer.py --truths 10 --out /tmp/boxtransfer
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

import box_truths  # noqa: E402
import make_box_example as box  # noqa: E402

from bayescal.config import load_study  # noqa: E402
from bayescal.examples import copy_example  # noqa: E402
from bayescal.metrics import honest_range  # noqa: E402
from bayescal.pipeline import Options, load_results, run  # noqa: E402
from bayescal.pipeline.newdata import predict_as  # noqa: E402


def _phase(mode: str, folder: Path, index: int, values: dict[str, float]) -> None:
    name = f"box-{mode}"
    shutil.rmtree(folder, ignore_errors=True)
    copy_example(name, folder)
    table = box.make_phase(mode, np.random.default_rng(box_truths.SEED + index), values)
    table.to_parquet(folder / "data" / f"{name}.parquet", index=False, compression="zstd")


def _sequential(
    index: int, values: dict[str, float], coheating: Path, freefloat: Path, start: float
) -> dict:
    """Calibrate the free-float phase with the co-heating posterior as prior."""
    study = freefloat / "study.toml"
    text = study.read_text(encoding="utf-8")
    text, count = re.subn(
        r"^\[study\]\n", f'[study]\nprior_from = "{coheating}"\n', text, flags=re.M
    )
    assert count == 1, "the free-float example's [study] table"
    study.write_text(text, encoding="utf-8")
    res = run(load_study(freefloat), until="predict", options=Options())
    seconds = time.perf_counter() - start
    post = res.posterior
    assert post is not None
    assert res.predictions is not None
    lower, upper = post.interval(0.95)
    row: dict = {"truth": index, "seconds": round(seconds, 1)}
    for j, p in enumerate(post.names):
        row[f"{p}_covered"] = bool(lower[j] <= values[p] <= upper[j])
        row[f"{p}_width"] = float(upper[j] - lower[j])
    m = res.predictions.metrics
    r = m[(m["model"] == "calibrated") & (m["window"] == "test")].iloc[0]
    row |= {"coverage95": float(r["coverage95"]), "coverage50": float(r["coverage50"])}
    row |= {"n_eff95": float(r["n_eff95"]), "n_eff50": float(r["n_eff50"])}
    row |= {"rmse_calibrated": float(r["rmse"]), "rmse_nominal": float("nan")}
    row["rhat_max"] = float(np.nanmax(post.diagnostics.rhat))
    return _within(row)


def one_truth(
    index: int, values: dict[str, float], out: Path, kind: str | None, sequential: bool = False
) -> dict:
    coheating, freefloat = out / f"coheating-{index}", out / f"freefloat-{index}"
    _phase("coheating", coheating, index, values)
    if kind is not None:
        box_truths.set_discrepancy(coheating / "study.toml", kind)
    _phase("freefloat", freefloat, index, values)
    study = freefloat / "study.toml"
    text = study.read_text(encoding="utf-8")
    sd = box.NOISE_SD["temp_air_in"]
    text, count = re.subn(
        r"^\[outputs\.errors\.temp_air_in\]\n",
        f"[outputs.errors.temp_air_in]\nsd = {sd}\n",
        text,
        flags=re.M,
    )
    assert count == 1, "the free-float example's [outputs.errors.temp_air_in] table"
    study.write_text(text, encoding="utf-8")
    start = time.perf_counter()
    run(load_study(coheating), until="calibrate", options=Options())
    results = load_results(load_study(coheating))
    if sequential:
        return _sequential(index, values, coheating, freefloat, start)
    pred = predict_as(results, load_study(freefloat))
    seconds = time.perf_counter() - start
    m = pred.metrics.set_index("model")
    cal, nom = m.loc["calibrated"], m.loc["nominal"]
    row: dict = {"truth": index, "seconds": round(seconds, 1)}
    post = results.posterior
    assert post is not None
    lower, upper = post.interval(0.95)
    for j, p in enumerate(post.names):
        row[f"{p}_covered"] = bool(lower[j] <= values[p] <= upper[j])
    row |= {
        "rmse_calibrated": float(cal["rmse"]),
        "rmse_nominal": float(nom["rmse"]),
        "coverage95": float(cal["coverage95"]),
        "coverage50": float(cal["coverage50"]),
        "n_eff95": float(cal["n_eff95"]),
        "n_eff50": float(cal["n_eff50"]),
    }
    return _within(row)


def _within(row: dict) -> dict:
    """The row with whether each band's coverage lies in its n_eff range."""
    low, high = honest_range(0.95, row["n_eff95"])
    row["within95"] = bool(low <= row["coverage95"] <= high)
    low, high = honest_range(0.5, row["n_eff50"])
    row["within50"] = bool(low <= row["coverage50"] <= high)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("box_transfer"))
    parser.add_argument("--discrepancy", choices=tuple(box_truths.DISCREPANCY))
    parser.add_argument("--keep", action="store_true", help="keep every truth's study folders")
    parser.add_argument(
        "--sequential",
        action="store_true",
        help="calibrate the free-float phase with the co-heating posterior as its prior",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    suffix = (f"_{args.discrepancy}" if args.discrepancy else "") + (
        "_sequential" if args.sequential else ""
    )
    csv = args.out / f"box_transfer{suffix}.csv"
    rows = pd.read_csv(csv).to_dict("records") if csv.is_file() else []
    for i, values in enumerate(box_truths.truths(args.truths)):
        if i < len(rows):
            continue
        rows.append(one_truth(i, values, args.out, args.discrepancy, args.sequential))
        print(f"truth {i}: " + ", ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
        if not args.keep:
            for mode in ("coheating", "freefloat"):
                shutil.rmtree(args.out / f"{mode}-{i}", ignore_errors=True)
        partial = csv.with_suffix(".csv.part")
        pd.DataFrame(rows).to_csv(partial, index=False)
        partial.replace(csv)
    table = pd.DataFrame(rows)
    print(f"\n{len(table)} truths, co-heating posterior predicting the free-float phase:")
    for column in ("coverage95", "coverage50", "rmse_calibrated", "rmse_nominal"):
        values = table[column]
        print(f"  {column}: mean {values.mean():.3f}, median {values.median():.3f}, "
              f"range {values.min():.3f}-{values.max():.3f}")  # fmt: skip
    print(f"  95 % band within its n_eff range at {int(table['within95'].sum())} of {len(table)}")
    print(f"  50 % band within its n_eff range at {int(table['within50'].sum())} of {len(table)}")
    for column in [c for c in table.columns if c.endswith("_covered")]:
        print(f"  {column[: -len('_covered')]}: 95 % interval covers the truth at "
              f"{int(table[column].sum())} of {len(table)}")  # fmt: skip


if __name__ == "__main__":
    main()
