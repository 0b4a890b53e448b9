"""The virtual wall with two screening candidates and a Sobol screening to reuse.

``[design] reuse_screening`` (:mod:`bayescal.pipeline.reuse`): a 14-day virtual
wall record (:mod:`sequential_study`) calibrating the concrete's conductivity and
specific heat; the boards' conductivity and density are screening candidates
held at their nominal values, which are the truth's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bayescal.runner import sandbox
from screen_study import CANDIDATES as SCREEN_CANDIDATES
from sequential_study import END, write_study

EXECUTE = sandbox.execute
SCREENING_RUNS = 12
NEW_RUNS = 8
# screen_study's candidates, the density over a range in which it matters a little
CANDIDATES = SCREEN_CANDIDATES.replace(
    "lower = 116.0, upper = 117.0", "lower = 110.0, upper = 125.0"
)
assert CANDIDATES != SCREEN_CANDIDATES
SOBOL = f"""
[screening]
method = "sobol"
runs = {SCREENING_RUNS}
paths = 5
saltelli = 256
bootstrap = 50
"""


class Counting:
    """``sandbox.execute`` that counts the simulator runs."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, simulator: Any, forcing: Any, parameters: dict[str, float]) -> Any:
        self.calls += 1
        return EXECUTE(simulator, forcing, parameters)


def reuse_study(
    folder: Path,
    design: str = "reuse_screening = true\n",
    screening: str = SOBOL,
    runs: int = NEW_RUNS,
) -> Path:
    """The virtual wall's study with the two candidates, ``[design] runs = runs`` then the
    ``design`` lines, and ``screening``."""
    write_study(folder, END)
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    assert f"[design]\nruns = {NEW_RUNS}\n" in text
    text = text.replace(f"[design]\nruns = {NEW_RUNS}\n", f"[design]\nruns = {runs}\n{design}")
    path.write_text(text + CANDIDATES + screening, encoding="utf-8")
    return folder
