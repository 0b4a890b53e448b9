"""The paper's wall case study in full (docs/case-studies.md, section "The wall").

Three calibrations of the shipped ``wall`` example (a virtual experiment: real
weather, EnergyPlus truth at k_cb = 0.124, cp_cb = 845, cp_fb = 800, noise of
variance 0.007 (W/m²)²), printed as Markdown in the layout of the paper's
Tables 3 and 4:

1. the built-in wall with the example's settings and the difference process on;
2. the same emulator re-calibrated with the paper's Beta(1, 2) prior on cp_fb;
3. EnergyPlus itself as the simulator (the shipped ``paper_wall.epJSON``,
   conduction transfer functions), 30 runs, predictions by re-running it.

Usage (from the repository root; results go to ``out/case-studies/``)::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python scripts/wall_case_study.py [--skip-energyplus]
"""

from __future__ import annotations

import argparse
import shutil
import time
from importlib import resources
from pathlib import Path

import numpy as np

from bayescal.calibration.posterior import Posterior
from bayescal.config import load_study
from bayescal.demo import PAPER, TRUTH
from bayescal.design import BetaPrior
from bayescal.examples import copy_example
from bayescal.pipeline import Options, Results, run
from bayescal.pipeline.stages import calibrate_stage, prepare

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "out" / "case-studies"
PAPER_CI = {"k_cb": (0.123, 0.125), "cp_cb": (831.66, 859.07), "cp_fb": (731.44, 907.09)}

ENERGYPLUS = """[simulator]
type = "energyplus"
model = "paper_wall.epJSON"
algorithm = "ConductionTransferFunction"
weather = "from-forcing"

[simulator.schedules]
temp_surf_out = "TempSurfOut"
temp_surf_in = { schedule = "TempAirIn", lead_steps = 1 }

[simulator.outputs.heat_flux_in]
variable = "Surface Inside Face Conduction Heat Transfer Rate per Area"
key = "Wall"

"""
TARGETS = {
    '"concrete.conductivity"': '"Material:AeratedConcrete:Conductivity"',
    '"concrete.specific_heat"': '"Material:AeratedConcrete:Specific_Heat"',
    '"board_out.specific_heat", "board_in.specific_heat"': (
        '"Material:GlassFibreBoard:Specific_Heat"'
    ),
}


def _copy(name: str, edit: dict[str, str] | None = None) -> Path:
    folder = OUT / name
    shutil.rmtree(folder, ignore_errors=True)
    copy_example("wall", folder, force=True)
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    for old, new in (edit or {}).items():
        if old not in text:
            raise SystemExit(f"the wall example changed: {old!r} not found")
        text = text.replace(old, new)
    path.write_text(text, encoding="utf-8")
    return folder


def _energyplus_study() -> Path:
    folder = _copy("wall-energyplus", dict(TARGETS))
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    start, end = text.index("[simulator]"), text.index("[parameters.k_cb]")
    path.write_text(text[:start] + ENERGYPLUS + text[end:], encoding="utf-8")
    model = resources.files("bayescal.simulators") / "models" / "paper_wall.epJSON"
    shutil.copyfile(str(model), folder / "paper_wall.epJSON")
    return folder


def posterior_table(post: Posterior, title: str) -> str:
    """Table 3 layout: estimate and 95 % interval, with the truth and the paper's."""
    lower, upper = post.interval(0.95)
    mean = post.draws.reshape(-1, len(post.names)).mean(axis=0)
    rows = [
        f"**{title}**",
        "",
        "| parameter | truth | estimate | 95 % interval | paper estimate | paper 95 % c.i. |",
        "|---|---|---|---|---|---|",
    ]
    for k, n in enumerate(post.names):
        lo, hi = PAPER_CI[n]
        rows.append(
            f"| {n} | {TRUTH[n]:.4g} | {mean[k]:.4g} | [{lower[k]:.4g}, {upper[k]:.4g}] "
            f"| {PAPER[n]:.4g} | [{lo:.4g}, {hi:.4g}] |"
        )
    diag = "all pass" if not post.warnings else "; ".join(post.warnings)
    rows += ["", f"Diagnostics: {diag}."]
    return "\n".join(rows)


def error_table(res: Results, title: str) -> str:
    """Table 4 layout: MSE and maximum absolute error on training and test windows."""
    assert res.predictions is not None
    m = res.predictions.metrics.set_index(["model", "window"])
    rows = [
        f"**{title}**",
        "",
        "| model | train MSE | train max abs error | test MSE | test max abs error |",
        "|---|---|---|---|---|",
    ]
    for model in ("nominal", "calibrated", "calibrated+delta"):
        if (model, "train") not in m.index:
            continue
        tr, te = m.loc[(model, "train")], m.loc[(model, "test")]
        rows.append(
            f"| {model} | {tr['mse']:.4f} | {tr['max_abs_error']:.3f} | {te['mse']:.4f} "
            f"| {te['max_abs_error']:.3f} |"
        )
    rows.append("| paper: ESP-r | 0.007 | 0.29 | 0.017 | 0.36 |")
    rows.append("| paper: ESP-r + Delta(x) | 0.004 | 0.27 | 0.017 | 0.36 |")
    return "\n".join(rows)


def _timed(folder: Path) -> tuple[Results, float]:
    t0 = time.perf_counter()
    res = run(load_study(folder), options=Options())
    return res, time.perf_counter() - t0


def main() -> None:
    """Run the three calibrations and print Markdown."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-energyplus", action="store_true")
    args = parser.parse_args()

    folder = _copy("wall", {"[emulator]": "[discrepancy]\nenabled = true\n\n[emulator]"})
    res, seconds = _timed(folder)
    assert res.posterior is not None
    assert res.emulator is not None
    print(posterior_table(res.posterior, "Built-in wall (finite volumes), uniform priors"))
    print()
    print(error_table(res, "Built-in wall: MSE [(W/m²)²] and maximum absolute error [W/m²]"))
    if res.discrepancy is not None:
        print()
        print(posterior_table(res.discrepancy.posterior, "Built-in wall, discrepancy phase"))
        explained = ", ".join(f"{k} {v:.2f}" for k, v in res.discrepancy.explained.items())
        print(f"\nShare of the training residual variance explained by Delta: {explained}.")
    print(f"\nRun time (all stages, report included): {seconds:.0f} s.")

    ctx = prepare(load_study(folder), Options())
    priors = dict(ctx.priors)
    old = priors["cp_fb"]
    priors["cp_fb"] = BetaPrior(old.lower, old.upper, 1.0, 2.0)
    beta = calibrate_stage(ctx, res.emulator, priors)
    print()
    print(posterior_table(beta, "Built-in wall, Beta(1, 2) prior on cp_fb"))
    sd_u = float(np.std(res.posterior.draws[..., 2]))
    sd_b = float(np.std(beta.draws[..., 2]))
    print(f"\ncp_fb posterior SD: uniform prior {sd_u:.1f}, Beta(1, 2) prior {sd_b:.1f} J/(kg·K).")

    if not args.skip_energyplus:
        eplus = _energyplus_study()
        res_e, seconds_e = _timed(eplus)
        assert res_e.posterior is not None
        print()
        print(posterior_table(res_e.posterior, "EnergyPlus (CTF) as the simulator"))
        print()
        print(error_table(res_e, "EnergyPlus: MSE [(W/m²)²] and maximum absolute error [W/m²]"))
        print(f"\nRun time (all stages, report included): {seconds_e:.0f} s.")


if __name__ == "__main__":
    main()
