"""Every shipped example's report in a real browser (headless Chromium), cut short.

``test_browser`` checks the wall example's page in detail (with a ``[derived]``
expression); this module renders the page of each other example, run end to end
at a small size (short chains, a few prediction runs; the office calibrates two
influential parameters of the shipped screening on a dozen EnergyPlus runs, the
others fixed at their catalogue values), with the same checks: no sideways
scrolling at 1400 and 900 px, every image loaded, no console message. Slow (each
example runs end to end); skipped without ``chromium``, and for the Twin House
where ``../shared/data`` is absent (a fresh clone without the measurements).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import pytest
import tomli_w
from test_browser import CHROMIUM, check_page

from bayescal.config import load_study
from bayescal.examples import copy_example
from bayescal.pipeline import Options, run

pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed"),
    pytest.mark.slow,
]

REPO = Path(__file__).resolve().parents[2]
TWIN_HOUSE = (
    REPO.parent / "shared" / "data" / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"
)
#: The office's parameters calibrated here (the two first of the shipped screening).
OFFICE = ("heating_setpoint", "outdoor_air")


def _tiny(folder: Path, name: str) -> None:
    path = folder / "study.toml"
    data: dict[str, Any] = tomllib.loads(path.read_text(encoding="utf-8"))
    if name == "office":
        for key, spec in data["parameters"].items():
            spec["screen"] = key not in OFFICE
    if name == "office":  # EnergyPlus: few runs; the others' simulators take ~0.1 s a run
        data["design"] = {"runs": 12}
    data.setdefault("emulator", {})["samples"] = 50
    cal = data.setdefault("calibration", {})
    cal.update(chains=4, burn=150, samples=150, max_samples=150)
    pred = data.setdefault("predict", {})
    pred.update(runs=10, draws=50)
    if "discrepancy" in data and data["discrepancy"].get("enabled"):
        data["discrepancy"].update(burn=100, samples=100, max_samples=100)
    path.write_text(tomli_w.dumps(data), encoding="utf-8")


@pytest.fixture(scope="module", params=["box-coheating", "box-freefloat", "twinhouse", "office"])
def report(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    name = request.param
    folder = copy_example(name, tmp_path_factory.mktemp("examples") / name)
    if name == "twinhouse":
        if not TWIN_HOUSE.is_file():
            pytest.skip(f"{TWIN_HOUSE.parent.parent} is absent (a fresh clone without ../shared)")
        (folder / "data").mkdir(exist_ok=True)
        (folder / "data" / TWIN_HOUSE.name).symlink_to(TWIN_HOUSE)  # read in place
    _tiny(folder, name)
    run(load_study(folder), options=Options(backend="serial", chains_backend="serial"))
    page = folder / "out" / "report" / "report.html"
    assert page.is_file()
    return page


@pytest.mark.parametrize("width", [1400, 900])
def test_every_examples_report_fits_the_screen_and_loads_every_image(
    report: Path, width: int, tmp_path: Path
) -> None:
    check_page(report, width, tmp_path, images=6)
    text = report.read_text(encoding="utf-8")
    first = text[: text.index("<details><summary><h2>")]
    for shown in ("Converged?", "Did the calibration help?", "Do the bands hold?"):
        assert shown in first
