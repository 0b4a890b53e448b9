"""The test box's two phases calibrated together (``bayescal joint``) and in sequence.

For ``--truths`` truths (those of ``box_truths.py``: a seeded Latin hypercube over
the middle 80 % of each prior; data by EnergyPlus at the truth, seed ``SEED + i``,
as ``box_transfer.py`` makes them), each truth's

* co-heating phase is calibrated (the ``box-coheating`` example as shipped);
* free-float phase is calibrated alone (the ``box-freefloat`` example as shipped);
* joint calibration of both is run (:mod:`bayescal.pipeline.joint`);
* free-float phase is calibrated again with the co-heating posterior as its
  prior (``[study] prior_from``): the sequential calibration, on the same design
  and emulator as the free-float study alone.

A row per truth: for each parameter the joint and the sequential mean, SD and 95 %
interval, their difference in joint SDs, the ratio of the interval widths, whether
each interval covers the truth, and the diagnostics. Writes ``box_joint.csv`` into
``--out`` after every truth (a run started again keeps the truths it finished).

Run (each truth is about four to six minutes on the idle 2-core machine)::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python scripts/box_joint.py --truths 10 --out /tmp/boxjoint
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
from box_transfer import _phase  # noqa: E402

from bayescal.calibration.posterior import Posterior  # noqa: E402
from bayescal.config import load_study  # noqa: E402
from bayescal.pipeline import Options, load_results, run  # noqa: E402
from bayescal.pipeline.joint import joint  # noqa: E402


def _calibrated(folder: Path) -> tuple[Posterior, float]:
    start = time.perf_counter()
    run(load_study(folder), until="calibrate", options=Options())
    post = load_results(load_study(folder)).posterior
    assert post is not None
    return post, time.perf_counter() - start


def _stats(post: Posterior, name: str) -> tuple[float, float, float, float]:
    column = post.draws.reshape(-1, len(post.names))[:, post.names.index(name)]
    low, high = np.quantile(column, [0.025, 0.975])
    return float(column.mean()), float(column.std(ddof=1)), float(low), float(high)


def one_truth(index: int, values: dict[str, float], out: Path) -> dict:
    coheating, freefloat = out / f"coheating-{index}", out / f"freefloat-{index}"
    _phase("coheating", coheating, index, values)
    _phase("freefloat", freefloat, index, values)
    _, t_co = _calibrated(coheating)
    _, t_ff = _calibrated(freefloat)
    start = time.perf_counter()
    together = joint([coheating, freefloat], out / f"joint-{index}")
    t_joint = time.perf_counter() - start
    sequential = out / f"sequential-{index}"
    shutil.rmtree(sequential, ignore_errors=True)
    shutil.copytree(freefloat, sequential)
    study = sequential / "study.toml"
    text, count = re.subn(
        r"^\[study\]\n",
        f'[study]\nprior_from = "{coheating}"\n',
        study.read_text(encoding="utf-8"),
        flags=re.M,
    )
    assert count == 1, "the free-float example's [study] table"
    study.write_text(text, encoding="utf-8")
    seq, t_seq = _calibrated(sequential)
    post = together.posterior
    row: dict = {
        "truth": index,
        "seconds_coheating": round(t_co, 1),
        "seconds_freefloat": round(t_ff, 1),
        "seconds_joint": round(t_joint, 1),
        "seconds_sequential": round(t_seq, 1),
        "joint_ok": post.diagnostics.ok,
        "sequential_ok": seq.diagnostics.ok,
        "joint_warnings": len(together.warnings),
    }
    for name in post.names:
        jm, js, jl, jh = _stats(post, name)
        sm, ss, sl, sh = _stats(seq, name)
        row |= {
            f"{name}_truth": values[name],
            f"{name}_joint_mean": jm,
            f"{name}_joint_sd": js,
            f"{name}_seq_mean": sm,
            f"{name}_seq_sd": ss,
            f"{name}_shift_sd": (sm - jm) / js,
            f"{name}_width_ratio": (sh - sl) / (jh - jl),
            f"{name}_joint_covered": bool(jl <= values[name] <= jh),
            f"{name}_seq_covered": bool(sl <= values[name] <= sh),
        }
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("box_joint"))
    parser.add_argument("--keep", action="store_true", help="keep every truth's study folders")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    csv = args.out / "box_joint.csv"
    rows = pd.read_csv(csv).to_dict("records") if csv.is_file() else []
    for i, values in enumerate(box_truths.truths(args.truths)):
        if i < len(rows):
            continue
        rows.append(one_truth(i, values, args.out))
        print(f"truth {i}: " + ", ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
        if not args.keep:
            for prefix in ("coheating", "freefloat", "joint", "sequential"):
                shutil.rmtree(args.out / f"{prefix}-{i}", ignore_errors=True)
        partial = csv.with_suffix(".csv.part")
        pd.DataFrame(rows).to_csv(partial, index=False)
        partial.replace(csv)
    table = pd.DataFrame(rows)
    n = len(table)
    print(f"\n{n} truths, joint (co-heating x free-float) against sequential (prior_from):")
    names = [c[: -len("_shift_sd")] for c in table.columns if c.endswith("_shift_sd")]
    for name in names:
        shift = table[f"{name}_shift_sd"].abs()
        ratio = table[f"{name}_width_ratio"]
        print(
            f"  {name}: |shift| median {shift.median():.2f}, max {shift.max():.2f} joint SD "
            f"(<= 0.2 at {int((shift <= 0.2).sum())} of {n}); width ratio "
            f"{ratio.min():.2f}-{ratio.max():.2f} (within 10 % at "
            f"{int(((ratio - 1).abs() <= 0.1).sum())} of {n}); 95 % covers the truth: joint "
            f"{int(table[f'{name}_joint_covered'].sum())}, sequential "
            f"{int(table[f'{name}_seq_covered'].sum())} of {n}"
        )
    for column in ("joint_ok", "sequential_ok"):
        print(f"  {column}: {int(table[column].sum())} of {n}")
    for column in [c for c in table.columns if c.startswith("seconds_")]:
        print(f"  {column}: median {table[column].median():.1f}")


if __name__ == "__main__":
    main()
