"""``bayescal predict --data`` over known truths: how the bands hold on another weather.

For each of ``--truths`` truths (k_cb and cp_cb drawn as
``tests/helpers/virtual_wall.random_truth`` draws them, inside the middle 80 % of
the paper's priors; the boards keep the study's 840 J/(kg·K)) the script

1. writes a virtual-wall study (``tests/helpers/compare_study.STUDY`` at a
   realistic size: 1 warm-up day, ``--days`` training days, a 2-day test window,
   20 design runs, chains 4 x (500 + 1000), white errors; the data made by the
   built-in wall at the truth plus white noise of SD sqrt(0.007) W/m²,
   ``compare_study.wall_data``);
2. calibrates it (``bayescal.pipeline.run(study, until="calibrate")``);
3. makes another record of the same wall (same truth, another weather and noise
   seed, 1 warm-up day and ``--new-days`` days predicted) and predicts it with
   :func:`bayescal.pipeline.newdata.predict_new` (the study's ``[predict]``
   defaults: the simulator re-run at 50 posterior draws);
4. scores the calibrated prediction on that record: coverage of the 95 % and
   50 % bands with the range an honest band shows on its effective number of
   samples (:func:`bayescal.metrics.honest_range`), and the RMSE of the
   calibrated against the nominal model.

``--discrepancy`` adds ``discrepancy = true`` to ``[outputs.errors.heat_flux_in]``
(the in-likelihood discrepancy, kriged at the new record's conditions). The model
is the truth's own, so any width the discrepancy adds is not needed here.
``--noise basis`` sets ``[predict] noise = "basis"``: the discrepancy output's
noise from what its basis leaves of the re-run simulator's residuals (the default
keeps the calibration's lambda*, which also holds the emulator's error).

It prints one line per truth, the mean and pooled coverage over the truths, and
writes ``predict_truths_<variant>.csv`` and ``.json`` into ``--out``.

Run (each truth takes 5-15 s on the 2-core machine)::

    PYTHONPATH=src .venv/bin/python scripts/predict_truths.py --truths 10 --out /tmp/pt
    PYTHONPATH=src .venv/bin/python scripts/predict_truths.py --truths 10 --discrepancy \\
        --out /tmp/pt
    PYTHONPATH=src .venv/bin/python scripts/predict_truths.py --truths 10 --discrepancy \\
        --noise basis --out /tmp/pt
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from bayescal.config import load_study  # noqa: E402
from bayescal.metrics import honest_range  # noqa: E402
from bayescal.pipeline import Options, load_results, run  # noqa: E402
from bayescal.pipeline.newdata import predict_new  # noqa: E402
from compare_study import STUDY, wall_data  # noqa: E402
from virtual_wall import random_truth  # noqa: E402

SEED = 20261128
#: Seeds of the study's record and of the new record for truth ``i``: ``+ i``.
STUDY_SEED, NEW_SEED = 1000, 2000
CALIBRATED = ("k_cb", "cp_cb")


def study_text(
    name: str, seed: int, discrepancy: bool, test_days: int = 2, noise: str = "simulator"
) -> str:
    """compare_study.STUDY at the size of this check (``noise``: ``[predict] noise``)."""
    text = STUDY.format(name=name, model="white")
    edits = {
        "seed = 11\n": f"seed = {seed}\n",
        "test_samples = 48\n": f"test_samples = {48 * test_days}\n",
        "[design]\nruns = 8\n": "[design]\nruns = 20\n",
        "burn = 60\nsamples = 20\n": "",  # the emulator's defaults
        "burn = 150\nsamples = 200\nmax_samples = 200\n": (
            "burn = 500\nsamples = 1000\nmax_samples = 1000\n"
        ),
    }
    if discrepancy:
        edits['model = "white"\n'] = 'model = "white"\ndiscrepancy = true\n'
    for old, new in edits.items():
        if text.count(old) != 1:
            raise RuntimeError(f"compare_study.STUDY changed: {old!r} not found once")
        text = text.replace(old, new)
    return text + f'\n[predict]\nnoise = "{noise}"\n'


def one_truth(
    index: int,
    truth: dict[str, float],
    folder: Path,
    *,
    discrepancy: bool,
    days: int,
    new_days: int,
    noise: str = "simulator",
) -> dict[str, object]:
    """Calibrate at ``truth``, predict another record, score it."""
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    data = wall_data(seed=STUDY_SEED + index, days=days, phi=0.0, truth=truth, test_days=2)
    data.to_csv(folder / "wall.csv", index=False)
    (folder / "study.toml").write_text(
        study_text(folder.name, 11 + index, discrepancy, noise=noise), encoding="utf-8"
    )
    study = load_study(folder)
    options = Options(backend="serial")
    start = time.perf_counter()
    run(study, until="calibrate", options=options)
    calibrate_s = time.perf_counter() - start
    results = load_results(study)
    post = results.posterior
    assert post is not None
    # another winter: 1 warm-up day, new_days - 1 "training" and 1 "test" day in the
    # helper's terms, all of them predicted after the study's warm-up
    new = wall_data(seed=NEW_SEED + index, days=new_days - 1, phi=0.0, truth=truth, test_days=1)
    path = folder / "other.csv"
    new.to_csv(path, index=False)
    start = time.perf_counter()
    pred = predict_new(results, path, options=options)
    predict_s = time.perf_counter() - start
    m = pred.metrics.set_index(["output", "model"])
    cal, nom = m.loc[("heat_flux_in", "calibrated")], m.loc[("heat_flux_in", "nominal")]
    row: dict[str, object] = {"truth": index}
    lower, upper = post.interval(0.95)
    for j, name in enumerate(post.names):
        row[f"{name}_true"] = truth[name]
        row[f"{name}_covered"] = bool(lower[j] <= truth[name] <= upper[j])
    row["rhat_max"] = float(np.nanmax(post.diagnostics.rhat))
    row["method"] = pred.method
    row["periods"] = int(pred.record.layout.test_starts.size)
    row["samples"] = int(pred.record.layout.test)
    for level, tag in ((0.95, "95"), (0.5, "50")):
        n_eff = float(cal[f"n_eff{tag}"])
        low, high = honest_range(level, n_eff)
        row[f"coverage{tag}"] = float(cal[f"coverage{tag}"])
        row[f"n_eff{tag}"] = n_eff
        row[f"honest{tag}"] = f"{low:.3f}-{high:.3f}"
        row[f"within{tag}"] = bool(low <= row[f"coverage{tag}"] <= high)
    row["band_scale"] = float(cal["band_scale"])  # the band's spread over the errors' RMS
    row["rmse_calibrated"] = float(cal["rmse"])
    row["rmse_nominal"] = float(nom["rmse"])
    row["calibrate_s"] = round(calibrate_s, 1)
    row["predict_s"] = round(predict_s, 1)
    return row


def summary(rows: list[dict[str, object]]) -> dict[str, float]:
    """Mean and pooled (sample-weighted) coverage over the truths, and how many held."""
    frame = pd.DataFrame(rows)
    n = frame["samples"].astype(float)
    out: dict[str, float] = {"truths": float(len(frame))}
    for tag in ("95", "50"):
        cover = frame[f"coverage{tag}"].astype(float)
        out[f"mean{tag}"] = float(cover.mean())
        out[f"pooled{tag}"] = float((cover * n).sum() / n.sum())
        out[f"within{tag}"] = float(frame[f"within{tag}"].sum())
    out["band_scale"] = float(frame["band_scale"].mean())
    out["rmse_calibrated"] = float(frame["rmse_calibrated"].mean())
    out["rmse_nominal"] = float(frame["rmse_nominal"].mean())
    return out


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--truths", type=int, default=10, help="number of truths (10)")
    parser.add_argument("--days", type=int, default=12, help="training days of the study (12)")
    parser.add_argument("--new-days", type=int, default=8, help="days predicted (8)")
    parser.add_argument("--discrepancy", action="store_true", help="in-likelihood discrepancy")
    parser.add_argument(
        "--noise",
        choices=("simulator", "basis", "calibration"),
        default="simulator",
        help="[predict] noise of the studies (default: simulator, the study-file default)",
    )
    parser.add_argument("--out", type=Path, default=None, help="folder for the CSV and JSON")
    parser.add_argument("--keep", action="store_true", help="keep the study folders in --out")
    args = parser.parse_args(argv)
    variant = "discrepancy" if args.discrepancy else "white"
    if args.noise != "simulator":
        variant += f"-noise-{args.noise}"
    rng = np.random.default_rng(SEED)
    truths = [
        {k: v for k, v in random_truth(rng).items() if k in CALIBRATED} for _ in range(args.truths)
    ]
    work = Path(tempfile.mkdtemp(prefix="predict_truths_"))
    root = args.out / "studies" if args.keep and args.out else work
    rows: list[dict[str, object]] = []
    try:
        for i, truth in enumerate(truths):
            row = one_truth(
                i,
                truth,
                root / f"{variant}-{i}",
                discrepancy=args.discrepancy,
                days=args.days,
                new_days=args.new_days,
                noise=args.noise,
            )
            rows.append(row)
            print(
                f"truth {i}: k_cb {truth['k_cb']:.4f} cp_cb {truth['cp_cb']:.1f}  "
                f"95 % {row['coverage95']:.3f} ({row['honest95']}, n_eff {row['n_eff95']:.0f})  "
                f"50 % {row['coverage50']:.3f} ({row['honest50']}, n_eff {row['n_eff50']:.0f})  "
                f"RMSE {row['rmse_calibrated']:.4f} vs nominal {row['rmse_nominal']:.4f}  "
                f"[{row['calibrate_s']} s + {row['predict_s']} s]",
                flush=True,
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    total = summary(rows)
    print(
        f"{variant}, {len(rows)} truths, {rows[0]['samples']} samples each: "
        f"95 % band mean {total['mean95']:.3f} (pooled {total['pooled95']:.3f}, "
        f"{total['within95']:.0f} within the honest range), "
        f"50 % band mean {total['mean50']:.3f} (pooled {total['pooled50']:.3f}, "
        f"{total['within50']:.0f} within); RMSE {total['rmse_calibrated']:.4f} "
        f"vs nominal {total['rmse_nominal']:.4f} W/m2 (means)"
    )
    report: dict[str, object] = {"variant": variant, "summary": total, "truths": rows}
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(rows).to_csv(args.out / f"predict_truths_{variant}.csv", index=False)
        (args.out / f"predict_truths_{variant}.json").write_text(
            json.dumps(report, indent=1), encoding="utf-8"
        )
    return report


if __name__ == "__main__":
    main()
