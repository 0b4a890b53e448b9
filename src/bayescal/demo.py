"""``make demo``: the paper's wall example, calibrated end to end.

Copies the shipped ``wall`` example into ``demo-out/wall``, validates it, runs
the built-in wall simulator at the nominal parameters and at the virtual
experiment's true parameters (fit metrics and figures), then runs the whole
calibration (design, 30 simulator runs, emulator, MCMC, predictions, report)
and compares the posterior with the known truth and with the paper's Table 3.

Run as ``python -m bayescal.demo [FOLDER]``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from bayescal import pipeline
from bayescal.cli.progress import describe, metrics_text, progress_options, study_summary
from bayescal.config import load_study
from bayescal.data import load_measured
from bayescal.errors import BayescalError
from bayescal.examples import copy_example
from bayescal.simulate import check_simulation, write_simulation

TRUTH = {"k_cb": 0.124, "cp_cb": 845.0, "cp_fb": 800.0}
"""True parameters of the example's virtual experiment (see its data/README.md)."""


#: The paper's estimates (Table 3), for comparison.
PAPER = {"k_cb": 0.124, "cp_cb": 845.41, "cp_fb": 799.71}


def run_demo(folder: Path, *, calibrate: bool = True, quiet: bool = False) -> list[Path]:
    """Run the demo in ``folder``; returns the figures (and the report) written."""
    say = (lambda _: None) if quiet else print
    copy_example("wall", folder, force=True)
    study = load_study(folder)
    say(study_summary(study, load_measured(study)))
    figures = []
    for label, values in (("nominal", {}), ("truth", TRUTH)):
        t0 = time.perf_counter()
        check = check_simulation(study, values)
        elapsed = time.perf_counter() - t0
        shown = ", ".join(f"{k}={v:g}" for k, v in check.parameters.items())
        say(f"\n{label} parameters ({shown}); load + simulate took {elapsed:.2f} s")
        say(metrics_text(check.train, check.test))
        files = write_simulation(check, study.study.output_dir / f"simulate-{label}", title=shown)
        figures.append(files["png"])
    if not calibrate:
        return figures
    say("\ncalibration (bayescal run):")
    t0 = time.perf_counter()
    res = pipeline.run(study, options=pipeline.Options(**progress_options(quiet)), say=say)
    say(describe(res))
    say(f"\ncalibration took {time.perf_counter() - t0:.1f} s")
    say(truth_table(res))
    if res.report is not None:
        figures.append(res.report)
    return figures


def truth_table(res: pipeline.Results) -> str:
    """Posterior against the virtual experiment's truth and the paper's estimates."""
    post = res.posterior
    if post is None:
        return ""
    lower, upper = post.interval(0.95)
    mean = post.draws.reshape(-1, len(post.names)).mean(axis=0)
    rows = [
        f"{'parameter':<10}{'truth':>10}{'paper':>10}{'mean':>10}{'95 % interval':>24}  covered"
    ]
    for k, name in enumerate(post.names):
        interval = f"[{lower[k]:.4g}, {upper[k]:.4g}]"
        hit = "yes" if lower[k] <= TRUTH[name] <= upper[k] else "NO"
        rows.append(
            f"{name:<10}{TRUTH[name]:>10.4g}{PAPER[name]:>10.4g}{mean[k]:>10.4g}"
            f"{interval:>24}  {hit}"
        )
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m bayescal.demo``."""
    args = sys.argv[1:] if argv is None else argv
    folder = Path(args[0]) if args else Path("demo-out") / "wall"
    try:
        figures = run_demo(folder)
    except BayescalError as exc:
        print(f"error: {exc.one_line()}", file=sys.stderr)
        return 2
    print("\nfigures and report:")
    for fig in figures:
        print(f"  {fig}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
