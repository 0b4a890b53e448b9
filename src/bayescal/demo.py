"""``make demo``: the paper's wall example, end to end as far as bayescal goes today.

Copies the shipped ``wall`` example into ``demo-out/wall``, validates it, runs
the built-in wall simulator on the measured boundary conditions at the nominal
parameters and at the virtual experiment's true parameters, prints the fit
metrics and says where the figures are.

Run as ``python -m bayescal.demo [FOLDER]``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from bayescal.cli import copy_example, metrics_table, summary
from bayescal.config import load_study
from bayescal.data import load_measured
from bayescal.errors import BayescalError
from bayescal.simulate import check_simulation, write_simulation

TRUTH = {"k_cb": 0.124, "cp_cb": 845.0, "cp_fb": 800.0}
"""True parameters of the example's virtual experiment (see its data/README.md)."""


def run_demo(folder: Path) -> list[Path]:
    """Run the demo in ``folder``; returns the figures written."""
    copy_example("wall", folder, force=True)
    study = load_study(folder)
    print(summary(study, load_measured(study)))
    figures = []
    for label, values in (("nominal", {}), ("truth", TRUTH)):
        t0 = time.perf_counter()
        check = check_simulation(study, values)
        elapsed = time.perf_counter() - t0
        shown = ", ".join(f"{k}={v:g}" for k, v in check.parameters.items())
        print(f"\n{label} parameters ({shown}); load + simulate took {elapsed:.2f} s")
        print(metrics_table(check.train, check.test))
        files = write_simulation(check, study.study.output_dir / f"simulate-{label}", title=shown)
        figures.append(files["png"])
    return figures


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m bayescal.demo``."""
    args = sys.argv[1:] if argv is None else argv
    folder = Path(args[0]) if args else Path("demo-out") / "wall"
    try:
        figures = run_demo(folder)
    except BayescalError as exc:
        print(f"error: {exc.one_line()}", file=sys.stderr)
        return 2
    print("\nfigures:")
    for fig in figures:
        print(f"  {fig}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
