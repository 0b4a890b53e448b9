"""The fixture wall with two screening candidates, for the ``bayescal screen`` tests."""

from __future__ import annotations

import shutil
from pathlib import Path

from bayescal.pipeline import Options
from paths import FIXTURES

#: Everything in the test process: no workers.
SERIAL = Options(backend="serial", chains_backend="serial")
#: The boards' conductivity (it matters) and density (over 1 kg/m³ it cannot), both candidates.
CANDIDATES = """
[parameters.k_fb]
# a candidate: the boards' conductivity
unit = "W/(m·K)"
nominal = 0.0316
prior = { distribution = "uniform", lower = 0.025, upper = 0.04 }
targets = ["board_out.conductivity", "board_in.conductivity"]
screen = true

[parameters.d_fb]
unit = "kg/m3"
nominal = 116.6
prior = { distribution = "uniform", lower = 116.0, upper = 117.0 }
targets = ["board_out.density", "board_in.density"]
screen = true
"""


def screen_study(tmp_path: Path, screening: str, name: str = "wall") -> Path:
    """A copy of the fixture wall study in ``tmp_path / name``, with :data:`CANDIDATES`.

    Parameters
    ----------
    tmp_path
        Where the study folder goes.
    screening
        The body of the study file's ``[screening]`` table (TOML lines).
    name
        The study folder's name.
    """
    target = tmp_path / name
    shutil.copytree(FIXTURES / "wall-study", target)
    path = target / "study.toml"
    text = path.read_text(encoding="utf-8") + CANDIDATES + "\n[screening]\n" + screening
    path.write_text(text, encoding="utf-8")
    return target
