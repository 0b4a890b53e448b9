"""The first screen of the wall example's report, as the README and the tutorial show it.

Copies the ``wall`` example into ``--out`` (as ``bayescal init wall`` does), runs it
with its own settings (a second call reuses every finished stage), and has headless
Chromium (Debian's ``chromium``) take a 1400 x 900 screenshot of its report, written
to ``docs/img/report-first-screen.png`` (or ``--png``).

Usage::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python scripts/report_screenshot.py [--out DIR] [--png FILE]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

from PIL import Image  # noqa: E402

from bayescal.config import load_study  # noqa: E402
from bayescal.examples import copy_example  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/screenshot/wall"))
    parser.add_argument(
        "--png", type=Path, default=REPO / "docs" / "img" / "report-first-screen.png"
    )
    opts = parser.parse_args()
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print("error: chromium is not installed (apt-get install -y chromium)", file=sys.stderr)
        return 2
    if not (opts.out / "study.toml").is_file():
        copy_example("wall", opts.out)
    res = run(load_study(opts.out), options=Options(), say=print)
    assert res.report is not None
    with tempfile.TemporaryDirectory() as tmp:
        shot = Path(tmp) / "shot.png"
        command = [
            chromium,
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--hide-scrollbars",
            "--window-size=1400,900",
            f"--screenshot={shot}",
            res.report.resolve().as_uri(),
        ]
        subprocess.run(command, capture_output=True, timeout=120, check=False)
        if not shot.is_file():
            print("error: chromium wrote no screenshot", file=sys.stderr)
            return 1
        opts.png.parent.mkdir(parents=True, exist_ok=True)
        # 256 colours keep the page's text sharp and the file small (docs images < 150 kB)
        with Image.open(shot) as image:
            image.convert("RGB").quantize(colors=256).save(opts.png, optimize=True)
    print(f"wrote {opts.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
