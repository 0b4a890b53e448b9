"""The report in a real browser: headless Chromium renders a small study's page.

Checked with the page's own script (a copy of the page with a few lines of
JavaScript that write their findings into ``<pre id="check">``, read back
with ``--dump-dom``; no DevTools protocol needed), every section unfolded:

* the page does not scroll sideways at 1400 x 900 nor at a narrow 900 x 900
  (``scrollWidth <= innerWidth``; wide tables scroll inside their own box);
* every image loaded (``complete`` and ``naturalWidth > 0``);
* no console message and no uncaught error (Chromium's ``--enable-logging=stderr``
  writes each as an ``INFO:CONSOLE`` line, which this test reads).

Marked slow (the small study runs end to end, about 25 s). Skipped where
``chromium`` is not installed (``apt-get install -y chromium``;
``.ci/run`` installs it where it can).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from bayescal.config import load_study
from bayescal.examples import copy_example
from bayescal.pipeline import Options, run

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: About 25 s on 2 cores (the study runs end to end): in the slow suite.
pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed"),
    pytest.mark.slow,
]

#: The wall example cut short: a dozen runs, short chains, a [derived] expression.
TINY = """
[design]
runs = 12

[emulator]
pca_variance = 0.99
history_periods = 1
training = "mcmc"
burn = 100
samples = 100

[calibration]
chains = 4
burn = 150
samples = 150
max_samples = 150

[predict]
method = "simulator"
runs = 10
draws = 50

[derived.r_concrete]
expression = "0.15 / k_cb"
unit = "m²·K/W"
description = "resistance of the concrete layer"
"""

CHECK = """<script>
window.addEventListener('load', function () {
  document.querySelectorAll('details').forEach(function (d) { d.open = true; });
  var vw = window.innerWidth, wide = [];
  function clipped(el) {
    for (var p = el.parentElement; p; p = p.parentElement) {
      var o = getComputedStyle(p).overflowX;
      if (o === 'auto' || o === 'scroll' || o === 'hidden') return true;
    }
    return false;
  }
  document.querySelectorAll('body *').forEach(function (el) {
    var r = el.getBoundingClientRect();
    if (r.right > vw + 0.5 && !clipped(el)) wide.push(el.tagName + ' ' + Math.round(r.width));
  });
  var imgs = Array.prototype.slice.call(document.images);
  var pre = document.createElement('pre');
  pre.id = 'check';
  pre.textContent = JSON.stringify({
    scrollWidth: document.documentElement.scrollWidth, innerWidth: vw,
    wide: wide.slice(0, 10), images: imgs.length,
    broken: imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); }).length
  });
  document.body.appendChild(pre);
});
</script>"""


def _chromium(page: Path, width: int, *extra: str) -> subprocess.CompletedProcess[str]:
    assert CHROMIUM is not None
    command = [
        CHROMIUM,
        "--headless",
        "--disable-gpu",
        "--no-sandbox",
        "--enable-logging=stderr",
        "--v=0",
        f"--window-size={width},900",
        "--virtual-time-budget=5000",
        *extra,
        page.as_uri(),
    ]
    return subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = copy_example("wall", tmp_path_factory.mktemp("browser") / "wall")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    text = text.replace("[design]\nruns = 30\n", "")
    path.write_text(text[: text.index("[emulator]")] + TINY, encoding="utf-8")
    run(load_study(folder), options=Options(backend="serial", chains_backend="serial"))
    return folder / "out" / "report" / "report.html"


def check_page(report: Path, width: int, tmp_path: Path, images: int) -> None:
    """The report at ``width``: no sideways scrolling, at least ``images`` images, all
    loaded, no console message or uncaught error."""
    page = tmp_path / "page.html"
    text = report.read_text(encoding="utf-8")
    page.write_text(text.replace("</body>", CHECK + "</body>"), encoding="utf-8")
    done = _chromium(page, width, "--dump-dom")
    found = re.search(r'<pre id="check">(.*?)</pre>', done.stdout, re.S)
    assert found, done.stderr[-2000:]
    check = json.loads(found.group(1).replace("&quot;", '"'))
    assert check["innerWidth"] == width
    assert check["scrollWidth"] <= check["innerWidth"], check["wide"]
    assert check["images"] >= images
    assert check["broken"] == 0
    # The page itself has no script: any console line (the check script writes none)
    # would be an error of the browser's reading of the page.
    console = [line for line in done.stderr.splitlines() if "CONSOLE" in line]
    assert not console, console
    assert "Uncaught" not in done.stderr


@pytest.mark.parametrize("width", [1400, 900])
def test_the_report_fits_the_screen_and_loads_every_image(
    report: Path, width: int, tmp_path: Path
) -> None:
    check_page(report, width, tmp_path, images=8)


def test_the_first_screen_shows_the_answer(report: Path, tmp_path: Path) -> None:
    """A screenshot of the first screen, and the text it shows: the verdicts, the fit
    and the calibrated quantities before any folded section."""
    shot = tmp_path / "first.png"
    done = _chromium(report, 1400, f"--screenshot={shot}")
    assert shot.is_file(), done.stderr[-2000:]
    assert shot.stat().st_size > 10_000
    text = report.read_text(encoding="utf-8")
    first = text[: text.index("<details><summary><h2>")]
    for shown in ("Converged?", "Did the calibration help?", "Do the bands hold?"):
        assert shown in first
    for quantity in ("k_cb", "U_value", "R_wall", "areal_heat_capacity", "r_concrete"):
        assert f"<td>{quantity}</td>" in first
    assert "<td>1.25</td>" in first  # r_concrete at the nominal k_cb = 0.12
