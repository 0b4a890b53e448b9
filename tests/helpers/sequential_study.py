"""A 14-day virtual wall record and its study cut at day eight (``prior_from``, ``update``).

The built-in wall at a known truth with white noise, half-hourly from
2012-02-01: one warm-up day and 13 daily periods. The study
(:data:`compare_study.STUDY`, white errors) ends on day eight by default, so
that a second study or ``bayescal update`` has the rest.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from compare_study import STUDY
from virtual_wall import virtual_experiment

#: The default truth (the boards as the study has them).
TRUTH = {"k_cb": 0.124, "cp_cb": 845.41, "cp_fb": 840.0}
#: Where the first study's record ends.
END = "2012-02-09T00:00"


def record(
    truth: dict[str, float] | None = None, seed: int = 5, periods: int = 13, test_days: int = 0
) -> pd.DataFrame:
    """The record at ``truth`` (default :data:`TRUTH`) with noise of ``seed``: one warm-up
    day, ``periods`` daily periods and ``test_days`` (default 14 days in all)."""
    ve = virtual_experiment(
        seed=seed, truth=truth or TRUTH, runs=5, periods=periods, warmup_days=1,
        test_days=test_days,
    )  # fmt: skip
    times = pd.date_range("2012-02-01", periods=ve.layout.n_total, freq="30min")
    return pd.DataFrame(
        {
            "time": times.strftime("%Y-%m-%dT%H:%M:%S"),
            "T_se": np.round(ve.boundary["temp_surf_out"], 6),
            "T_si": np.round(ve.boundary["temp_surf_in"], 6),
            "q_si": np.round(ve.measured["heat_flux_in"], 6),
        }
    )


def write_study(
    folder: Path, end: str | None = END, extra: str = "", data: pd.DataFrame | None = None
) -> Path:
    """``folder`` with ``wall.csv`` (``data``, default :func:`record`) and ``study.toml``
    ending at ``end`` (``None``: the whole record), ``extra`` added to ``[study]``."""
    folder.mkdir(parents=True, exist_ok=True)
    (record() if data is None else data).to_csv(folder / "wall.csv", index=False)
    text = STUDY.format(name=folder.name, model="white")
    if end is not None:
        text = text.replace('time_zone = "UTC"\n', f'time_zone = "UTC"\nend = "{end}"\n')
    text = text.replace("seed = 11\n", "seed = 11\n" + extra)
    (folder / "study.toml").write_text(text, encoding="utf-8")
    return folder


def second_study(folder: Path, prior_from: bool) -> Path:
    """``folder/second.toml``: the study of ``folder`` on its record from the first test
    window (less one warm-up) to the end, as ``bayescal update`` writes it, its results in
    ``out/second``; with ``prior_from`` the first study's posterior as its prior, else a
    study of its own (named ``<folder>-second``)."""
    text = (folder / "study.toml").read_text(encoding="utf-8")
    text = text.replace(f'end = "{END}"\n', 'start = "2012-02-07T00:00"\n')
    if prior_from:
        text = text.replace("seed = 11\n", 'seed = 11\nprior_from = "study.toml"\n')
    else:
        text = text.replace(f'name = "{folder.name}"', f'name = "{folder.name}-second"')
    text = text.replace("[data]", 'output_dir = "out/second"\n\n[data]', 1)
    path = folder / "second.toml"
    path.write_text(text, encoding="utf-8")
    return path


def interval_hits(post: Any, truth: dict[str, float], seen: list[str]) -> list[bool]:
    """Whether each parameter's 95 % interval of ``post`` holds its truth (a line each in
    ``seen``)."""
    lower, upper = post.interval(0.95)
    hits = []
    for k, name in enumerate(post.names):
        inside = bool(lower[k] <= truth[name] <= upper[k])
        hits.append(inside)
        seen.append(f"{name}={truth[name]:.4g} in [{lower[k]:.4g}, {upper[k]:.4g}]: {inside}")
    return hits


def calibrated_truths(root: Path, truths: int, seed: int = 34) -> Iterator[tuple[Path, dict]]:
    """``truths`` known truths of the wall (``k_cb`` and ``cp_cb`` from the inner 80 % of
    the priors, :func:`virtual_wall.random_truth` with ``default_rng(seed)``), each a
    14-day record with noise seed ``100 + case`` and its study in ``root/truth-<case>``
    calibrated on the first eight days: ``(folder, truth)`` one after another."""
    from bayescal.config import load_study
    from bayescal.pipeline import Options, run
    from virtual_wall import random_truth

    rng = np.random.default_rng(seed)
    for case in range(truths):
        truth = random_truth(rng) | {"cp_fb": 840.0}
        folder = root / f"truth-{case}"
        write_study(folder, data=record(truth, seed=100 + case))
        run(load_study(folder), until="calibrate", options=Options(backend="serial"))
        yield folder, truth
