"""A sequential calibration against one calibration on every day: the virtual wall.

The 14-day virtual wall of ``tests/helpers/sequential_study.py`` (the built-in
wall at a known truth, white noise, the record's noise seed 5): study A on
days 2-7, then ``bayescal update`` on days 8-13 with A's posterior as prior (B),
against study C on days 2-13 in one calibration. Each study has ``--runs``
design runs and 4 x (300 + 1000) sweeps; ``--seed`` is the studies' seed (design
and chains). ``--warmup`` is the update's (``all``, ``study`` or a duration);
``--study-warmup`` sets ``[periods] warmup`` of every study. B alone (the update's
study without the prior) is calibrated too, so that the update can be compared
with the precision-weighted product of A and B alone.

Prints, per parameter, the means and SDs, (B - C) in C's SD and the 95 % width
ratio B / C, and B against the product.

Run::

    .venv/bin/python scripts/sequential_joint.py --runs 16 --seed 11 --out /tmp/seqjoint
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tomllib  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import tomli_w  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "helpers"))

from bayescal.config import Study, load_study  # noqa: E402
from bayescal.pipeline import Options, load_results, run  # noqa: E402
from bayescal.pipeline.update import update  # noqa: E402
from sequential_study import write_study  # noqa: E402

OPTIONS = Options(backend="serial")


def _settings(folder: Path, runs: int, seed: int, study_warmup: str | None) -> Path:
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    text = text.replace("[design]\nruns = 8\n", f"[design]\nruns = {runs}\n")
    text = text.replace(
        "burn = 150\nsamples = 200\nmax_samples = 200",
        "burn = 300\nsamples = 1000\nmax_samples = 1000",
    )
    text = text.replace("seed = 11\n", f"seed = {seed}\n")
    if study_warmup is not None:
        text = text.replace('warmup = "1D"', f'warmup = "{study_warmup}"')
    path.write_text(text, encoding="utf-8")
    return folder


def _moments(study: Study) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]:
    post = load_results(study).posterior
    assert post is not None
    draws = post.draws.reshape(-1, len(post.names))
    lo, hi = np.percentile(draws, [2.5, 97.5], axis=0)
    return tuple(post.names), draws.mean(axis=0), draws.std(axis=0), hi - lo


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=16, help="design runs of each study (16)")
    parser.add_argument("--seed", type=int, default=11, help="the studies' seed (11)")
    parser.add_argument("--warmup", default="all", help="the update's warm-up (all)")
    parser.add_argument("--study-warmup", default=None, help="[periods] warmup of every study")
    parser.add_argument("--out", type=Path, default=Path("/tmp/seqjoint"))
    args = parser.parse_args(argv)
    label = f"r{args.runs}-s{args.seed}-{args.warmup}-{args.study_warmup or '1D'}"
    root = args.out / label
    if root.exists():
        shutil.rmtree(root)
    start = time.perf_counter()
    first = _settings(write_study(root / "a"), args.runs, args.seed, args.study_warmup)
    joint = _settings(write_study(root / "c", end=None), args.runs, args.seed, args.study_warmup)
    run(load_study(first), until="calibrate", options=OPTIONS)
    warmup = args.warmup if args.warmup in ("all", "study") else pd.Timedelta(args.warmup)
    done = update(load_study(first), options=OPTIONS, warmup=warmup)
    run(load_study(joint), until="calibrate", options=OPTIONS)
    assert done.study.path is not None
    raw = tomllib.loads(Path(done.study.path).read_text(encoding="utf-8"))
    del raw["study"]["prior_from"]
    raw["study"]["output_dir"] = "out/alone"
    alone_path = Path(done.study.path).parent / "alone.toml"
    alone_path.write_text(tomli_w.dumps(raw), encoding="utf-8")
    alone = load_study(alone_path)
    run(alone, until="calibrate", options=OPTIONS)
    names, ma, sa, _ = _moments(load_study(first))
    _, mb, sb, wb = _moments(done.study)
    _, mc, sc, wc = _moments(load_study(joint))
    _, m2, s2, _ = _moments(alone)
    print(f"{label}: A on days 2-7, B = update on days 8-13, C on days 2-13")
    for k, name in enumerate(names):
        w1, w2 = sa[k] ** -2, s2[k] ** -2
        product_mean = (w1 * ma[k] + w2 * m2[k]) / (w1 + w2)
        product_sd = (w1 + w2) ** -0.5
        print(
            f"  {name}: A {ma[k]:.6g} ± {sa[k]:.3g}, B {mb[k]:.6g} ± {sb[k]:.3g}, "
            f"C {mc[k]:.6g} ± {sc[k]:.3g}; (B - C) / SD_C {(mb[k] - mc[k]) / sc[k]:+.2f}, "
            f"width B / C {wb[k] / wc[k]:.3f}; B alone {m2[k]:.6g} ± {s2[k]:.3g}, "
            f"product {product_mean:.6g} ± {product_sd:.3g}, SD B / product "
            f"{sb[k] / product_sd:.3f}, SD C / product {sc[k] / product_sd:.3f}"
        )
    print(f"{time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
