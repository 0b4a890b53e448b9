"""The Twin House calibrated on two sensors: the inside heat flux and the in-wall temperature.

Issue 35 ("several sensors that converge"): the shipped Twin House study
(``bayescal init twinhouse``) calibrates the wall on the heat flux at the
inside surface and keeps the temperature inside the wall (column 16,
``westfacade_S_BL1_T`` = the wall's ``temp_interface_2``) as a held-out sensor.
This script builds the variant that calibrates on both and keeps a third
sensor out for the final check: the heat flux at the same layer boundary
(column 17, ``westfacade_S_BL1_HF`` = ``heat_flux_interface_2``). Both the data
and the simulator count that flux positive from outside to inside: its
correlation with the temperature drop across the EPS, outside surface (column
18) minus the boundary (column 16), is +0.997 on the training days, so the
column is mapped without a sign flip.

Variants (``--temp``, the temperature's error model; the flux keeps the
example's AR(1) errors and discrepancy):

``ar1``
    AR(1) errors and a discrepancy over the days' conditions, as the flux.
``white``
    White errors, no discrepancy.
``ar1-alone``
    AR(1) errors without a discrepancy (what a user who copies only the flux's
    ``model = "ar1"`` gets).
``flux-only``
    The shipped study (flux calibrated, the temperature held out) with the
    boundary flux held out as well: the baseline for the held-out plate.

The temperature's stated accuracy is the example's (0.1-0.5 K). The held-out
flux's stated accuracy is a range of 0.2-1.0 W/m² (set from a plate's physics
before its data were read, :data:`HELD_OUT_FLUX_SD`).

Each variant is copied from the shipped example into ``OUT/NAME`` (default
``out/twinhouse-sensors`` under the repository root, ignored by git), pointed
at ``../shared/data/annex58-twinhouse-n2-exp1/validationdataN2Exp1.txt`` in
place (as ``scripts/run_case_studies.py`` does) and run with the example's
calibration settings. The script prints what ``bayescal show`` prints, then
for each variant the worst R-hat and ESS, the AR(1) coefficients, and the
metrics of every output (the held-out flux included), calibrated against
the catalogue values. ``--compare`` also runs ``bayescal compare`` on the
variants (training days only) and prints its ranking.

Usage::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python scripts/twinhouse_sensors.py
        [--temp ar1 white ar1-alone flux-only] [--out DIR] [--fresh] [--compare]
        [--max-refits N]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd

from bayescal.cli.progress import comparison_text, describe
from bayescal.config import load_study
from bayescal.errors import BayescalError
from bayescal.pipeline import Options, Results, run
from bayescal.pipeline.compare import compare

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

from run_case_studies import CaseError, prepare_case, stage_times  # noqa: E402

#: The held-out plate's accuracy, a central 95 % range of its noise SD [W/m²]. A
#: plate embedded at the EPS / plaster boundary is calibrated to about 5 %; it sits
#: in the insulation's steep gradient, where its own conductance distorts the flux
#: lines around it (an operational error of 5-20 % in low-conductivity layers), and
#: reads a few tenths of a W/m² off at zero flux. The flux across 80 mm of EPS
#: (R ~ 2 m²K/W) under outside-surface swings of 10-20 K a day is a few W/m², so
#: 0.2 W/m² (a good plate, small flux) to 1.0 W/m² (20 % of 5 W/m²).
HELD_OUT_FLUX_SD = ("0.2 W/m2", "1.0 W/m2")

#: The temperature's error model per variant (lines of [outputs.errors.temp_interface_2];
#: ``None``: not calibrated, held out as in the shipped example).
TEMP_MODELS: dict[str, str | None] = {
    "ar1": 'model = "ar1"\ndiscrepancy = true\n',
    "white": 'model = "white"\n',
    "ar1-alone": 'model = "ar1"\n',
    "flux-only": None,
}

_SENSOR_EDITS = (
    # (old, new): each old text must occur exactly once in the example
    (
        'outputs = ["heat_flux_in", "temp_interface_2"]',
        'outputs = ["heat_flux_in", "temp_interface_2", "heat_flux_interface_2"]',
    ),
    (
        "[data.columns.heat_flux_in]\n",
        "[data.columns.heat_flux_interface_2]\n"
        "# westfacade_S_BL1_HF: the heat flux at the same boundary as column 16, positive\n"
        "# outside -> inside as the wall's interface fluxes (it follows the temperature\n"
        "# drop across the EPS, correlation +0.997 on the training days): no sign flip.\n"
        "source = 17\n"
        'unit = "W/m2"\n'
        "sign = 1\n"
        "\n"
        "[data.columns.heat_flux_in]\n",
    ),
)


#: What calibrating the temperature changes in [outputs].
_CALIBRATE_EDITS = (
    ('calibrate = ["heat_flux_in"]', 'calibrate = ["heat_flux_in", "temp_interface_2"]'),
    ('held_out = ["temp_interface_2"]', 'held_out = ["heat_flux_interface_2"]'),
)
_FLUX_ONLY_EDITS = (
    ('held_out = ["temp_interface_2"]', 'held_out = ["temp_interface_2", "heat_flux_interface_2"]'),
)


def _replace(text: str, edits: tuple[tuple[str, str], ...]) -> str:
    for old, new in edits:
        if text.count(old) != 1:
            raise CaseError(f"the Twin House example has no single line {old!r} to change")
        text = text.replace(old, new)
    return text


def variant_text(text: str, temp: str) -> str:
    """The example's study text with the boundary flux held out and, unless ``temp`` is
    ``"flux-only"``, the temperature calibrated with the error model ``temp``."""
    text = _replace(text, _SENSOR_EDITS)
    lines = TEMP_MODELS[temp]
    if lines is None:
        text = _replace(text, _FLUX_ONLY_EDITS)
    else:
        text = _replace(text, _CALIBRATE_EDITS)
        head = "[outputs.errors.temp_interface_2]\n"
        text = _replace(text, ((head, head + lines),))
    low, high = HELD_OUT_FLUX_SD
    text += (
        "\n[outputs.errors.heat_flux_interface_2]\n"
        "# A plate at the EPS / plaster boundary (scripts/twinhouse_sensors.py: calibration\n"
        "# ~5 %, flux-line distortion in the insulation 5-20 %, offset a few tenths).\n"
        f'sd = ["{low}", "{high}"]\n'
    )
    return text


def prepare(folder: Path, temp: str, *, fresh: bool) -> Path:
    """Copy the Twin House example into ``folder`` and make it the variant ``temp``."""
    prepare_case("twinhouse", folder, fresh=fresh)
    path = folder / "study.toml"
    path.write_text(variant_text(path.read_text(encoding="utf-8"), temp), encoding="utf-8")
    return folder


def diagnostics(res: Results) -> pd.DataFrame:
    """R-hat and bulk / tail ESS of every sampled coordinate, worst R-hat first."""
    assert res.posterior is not None
    table = res.posterior.summary()
    sampled = table[table["r_hat"].notna()]
    cols = ["mean", "sd", "lower", "upper", "r_hat", "ess_bulk", "ess_tail"]
    return sampled[cols].sort_values("r_hat", ascending=False)


def metrics(res: Results) -> pd.DataFrame:
    """Train / test RMSE, bias and band coverage of every output, catalogue and calibrated."""
    assert res.predictions is not None
    m = res.predictions.metrics
    cols = ["output", "model", "window", "rmse", "bias", "coverage95", "coverage50", "n_eff95"]
    return m[[c for c in cols if c in m.columns]]


def run_variant(folder: Path, options: Options) -> tuple[Results, float]:
    """Run one prepared study to its report; return the results and the seconds."""
    start = time.perf_counter()
    res = run(load_study(folder), until="report", options=options, say=print)
    return res, time.perf_counter() - start


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--temp", nargs="+", default=["ar1"], choices=sorted(TEMP_MODELS))
    parser.add_argument("--out", type=Path, default=REPO / "out" / "twinhouse-sensors")
    parser.add_argument("--fresh", action="store_true", help="delete earlier results first")
    parser.add_argument("--compare", action="store_true", help="also run bayescal compare")
    parser.add_argument("--max-refits", type=int, default=3)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Build and run the two-sensor variants; return the exit status."""
    args = _parse(argv)
    options = Options(chains_backend="processes")
    pd.set_option("display.width", 200)
    folders = []
    for temp in args.temp:
        folder = args.out / (temp if temp == "flux-only" else f"two-sensors-{temp}")
        try:
            prepare(folder, temp, fresh=args.fresh)
            res, seconds = run_variant(folder, options)
        except (BayescalError, CaseError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        folders.append(folder)
        print()
        print(describe(res))
        print()
        print(f"== {folder.name}: temperature errors {temp!r} ==")
        times = stage_times(res.context.out)
        print("stage times [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in times.items()))
        print(
            f"this invocation: {seconds:.1f} s (stages reused: {', '.join(res.reused) or 'none'})"
        )
        print("\nsampled coordinates, worst R-hat first:")
        print(diagnostics(res).to_string(float_format=lambda v: f"{v:.4g}"))
        print("\nmetrics (heat_flux_interface_2 is held out):")
        print(metrics(res).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    calibrated = [f for f in folders if f.name != "flux-only"]
    if args.compare and len(calibrated) >= 2:
        output = args.out / "compare"
        print(
            f"\nbayescal compare {' '.join(map(str, calibrated))} --output {output} "
            f"--max-refits {args.max_refits}"
        )
        try:
            result = compare(calibrated, output=output, max_refits=args.max_refits, say=print)
        except BayescalError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        print(comparison_text(result.table, result.notes, result.files, result.warnings))
    return 0


if __name__ == "__main__":
    sys.exit(main())
