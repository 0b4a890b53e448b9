"""How many days the ISO 9869-1 average method needs: virtual walls and the Twin House.

For each wall the in-situ U of the average method (``bayescal.iso9869``: cumulative
R = sum(T_si - T_se) / sum(q) over whole days, U = 1 / (0.13 + R + 0.04)) is
computed after every whole day and compared with the truth. Printed per wall:

* ``days_10``: the first day count from which U stays within ±10 % of the truth to
  the end of the record (``-`` if it never does);
* ``iso_day``: the first day count at which the standard's conditions (a), (b) and
  (c) all hold (``-`` if never), with the U there and its error;
* the error of U after 3, 5, 7, 10, 14, 21 and 28 days.

Walls (``--set``):

* ``wall``: the built-in wall of the ``wall`` example (the paper's wall) at
  ``--truths`` truths drawn by a seeded Latin hypercube over the middle 80 % of the
  example's priors (k_cb, cp_cb, cp_fb), driven by the example's surface
  temperatures (``data/wall.csv``: real Chicago weather, 34 days from 00:00), its
  inside flux plus white noise of variance 0.007 (W/m²)² as "measured";
* ``twinhouse-virtual``: the Twin House wall (``twinhouse`` example, catalogue
  layers) at truths drawn the same way over its four wall parameters (the plate's
  offset 0), driven by the measured Twin House surface temperatures, plus white
  noise of SD 0.2 W/m² (about the calibrated noise SD);
* ``twinhouse``: the measured Twin House west façade, against the catalogue U of
  the twinhouse example (its wall at the nominal values).

Every record is cut into 24-hour blocks from its first local midnight; the
simulated walls start in steady state with the first boundary values, as a real
campaign starts with a wall in whatever state it is.

The Twin House sets read ``../shared/data`` beside the repository root and are
skipped with a message where it is absent.

``--bayes D [D ...]`` adds the Bayesian side: the ``wall`` example (its own data,
EnergyPlus at the stated truth) and the ``twinhouse`` example are calibrated with
bayescal on a record cut to ``[data] end`` = the first local midnight + warm-up + D
training days + a one-day test window (``[periods] test_samples = 1 day``), with
reduced chains (``BAYES_SIZES``: 4 x (500 + 500) sweeps, no extension), up to the calibration.
Printed per D: the posterior mean and 95 % interval of the derived U-value, whether
it holds the truth (the wall) or the catalogue U (the Twin House, which is no
truth), and the ISO 9869 U of the same record (warm-up + training days, from the
first local midnight). Study folders go to ``--out`` (default ``out/iso9869``).

Run (seconds; with ``--bayes`` about a minute per calibration)::

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python scripts/iso9869_days.py --truths 10
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python scripts/iso9869_days.py --set twinhouse \
        --bayes 3 7 14 28
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime as dt  # noqa: E402
import re  # noqa: E402
import time  # noqa: E402
import tomllib  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy.stats import qmc  # noqa: E402

from bayescal import examples  # noqa: E402
from bayescal.config import (  # noqa: E402
    Study,
    UniformPriorSpec,
    build_simulator,
    load_study,
    nominal_parameters,
)
from bayescal.config.study import study_from_dict  # noqa: E402
from bayescal.data.measured import MeasuredData, load_measured  # noqa: E402
from bayescal.examples import copy_example  # noqa: E402
from bayescal.iso9869 import AverageMethod, average_method  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402
from bayescal.simulators.base import Derivable, Forcing  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
TWINHOUSE_FILE = (
    REPO.parent / "shared" / "data" / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"
)
SEED = 9869
REPORT_DAYS = (3, 5, 7, 10, 14, 21, 28)
BAND = 0.10
#: Truths drawn for the virtual Twin House walls of ``--bayes-virtual`` (their first ones).
VIRTUAL_TRUTHS = 10
#: The wall example's truth (its data/README.md: EnergyPlus at these values).
WALL_TRUTH = {"k_cb": 0.124, "cp_cb": 845.0, "cp_fb": 800.0}
#: Reduced sizes of the repeated calibrations (the examples' own design and error models).
BAYES_SIZES = """
[calibration]
chains = 4
burn = 500
samples = 500
max_samples = 500
"""


@dataclass(frozen=True)
class Wall:
    """One wall's record and its true U."""

    name: str
    truth_u: float
    am: AverageMethod


def wall_study() -> Study:
    return load_study(examples.path("wall"))


def twinhouse_study(file: Path = TWINHOUSE_FILE) -> Study | None:
    """The twinhouse example reading ``file`` (the measurements, or a virtual copy)."""
    if not TWINHOUSE_FILE.is_file():
        print(f"skipped: the Twin House measurements are not at {TWINHOUSE_FILE}")
        return None
    folder = examples.path("twinhouse")
    raw = tomllib.loads((folder / "study.toml").read_text(encoding="utf-8"))
    raw["data"]["file"] = file.as_posix()
    return study_from_dict(raw, root=folder, source=str(folder / "study.toml"))


def _midnight(data: MeasuredData) -> int:
    """Index of the first sample at local midnight."""
    local = pd.DatetimeIndex(data.times.astype("datetime64[ns]"), tz="UTC").tz_convert(data.zone)
    hits = np.flatnonzero((local.hour == 0) & (local.minute == 0))
    return int(hits[0])


def _analyse(data: MeasuredData, flux_in: np.ndarray) -> AverageMethod:
    """The average method from the first local midnight (``q = -heat_flux_in``)."""
    start = _midnight(data)
    per_day = round(86400.0 / data.step)
    t_in = np.asarray(data.forcing.series["temp_surf_in"])[start:]
    t_out = np.asarray(data.forcing.series["temp_surf_out"])[start:]
    return average_method(t_in, t_out, -flux_in[start:], per_day)


def _u(simulator: object, parameters: dict[str, float]) -> float:
    assert isinstance(simulator, Derivable)
    return float(simulator.derived(parameters)["U_value"])


def truths(study: Study, count: int, physical: list[str]) -> list[dict[str, float]]:
    """``count`` truths, a seeded Latin hypercube over the middle 80 % of the priors."""
    unit = qmc.LatinHypercube(d=len(physical), seed=SEED).random(count)
    out = []
    for row in unit:
        values = {}
        for name, u in zip(physical, row, strict=True):
            prior = study.parameters[name].prior
            assert isinstance(prior, UniformPriorSpec), f"{name}: the script draws uniform priors"
            lower, upper = float(prior.lower), float(prior.upper)
            values[name] = lower + (0.1 + 0.8 * u) * (upper - lower)
        out.append(values)
    return out


def virtual_walls(study: Study, count: int, noise_sd: float, label: str) -> list[Wall]:
    """The study's wall at ``count`` truths, driven by its measured boundary temperatures."""
    data = load_measured(study)
    simulator = build_simulator(study)
    nominal = nominal_parameters(study)
    physical = [
        n for n in study.parameters if not study.parameters[n].targets[0].startswith("measured.")
    ]
    rng = np.random.default_rng(SEED)
    walls = []
    for i, truth in enumerate(truths(study, count, physical)):
        parameters = {**nominal, **truth}
        flux = simulator.simulate(parameters, data.forcing)["heat_flux_in"]
        flux = flux + rng.normal(0.0, noise_sd, flux.size)
        name = f"{label} {i + 1}: " + ", ".join(f"{k}={v:.4g}" for k, v in truth.items())
        walls.append(Wall(name, _u(simulator, parameters), _analyse(data, flux)))
    return walls


def measured_twinhouse(study: Study) -> Wall:
    data = load_measured(study)
    simulator = build_simulator(study)
    catalogue = _u(simulator, nominal_parameters(study))
    return Wall(
        "Twin House N2 west, measured", catalogue, _analyse(data, data.outputs["heat_flux_in"])
    )


def summary(wall: Wall) -> dict[str, object]:
    am = wall.am
    error = am.u / wall.truth_u - 1.0
    outside = np.flatnonzero(~(np.abs(error) <= BAND))
    stays = int(am.days[outside[-1]] + 1) if outside.size else 1
    row: dict[str, object] = {
        "wall": wall.name,
        "U_true": round(wall.truth_u, 4),
        "days": int(am.days[-1]),
        "days_10": stays if stays <= am.days[-1] else "-",
    }
    day = am.first_converged
    row["iso_day"] = day if day is not None else "-"
    row["U_iso"] = round(float(am.u[day - 1]), 4) if day else "-"
    row["err_iso_%"] = round(100 * float(error[day - 1]), 1) if day else "-"
    row["U_end"] = round(float(am.u[-1]), 4)
    for d in REPORT_DAYS:
        if d <= am.days[-1]:
            row[f"err_{d}d_%"] = round(100 * float(error[d - 1]), 1)
    return row


def markdown(rows: list[dict[str, object]]) -> str:
    columns = list(dict.fromkeys(k for r in rows for k in r))
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(str(r.get(c, "")) for c in columns) + " |" for r in rows]
    return "\n".join(lines)


def curve(wall: Wall) -> str:
    """Day by day: R, U, its error and the three conditions."""
    rows: list[dict[str, object]] = []
    for r in wall.am.rows():
        err = 100 * (float(r["U"]) / wall.truth_u - 1.0)
        flags = "".join(k if r[k] else "." for k in ("a", "b", "c"))
        rows.append(
            {
                "D": r["days"],
                "R": f"{r['R']:.3f}",
                "U": f"{r['U']:.4f}",
                "err_%": f"{err:+.1f}",
                "abc": flags,
                "converged": "yes" if r["converged"] else "",
            }
        )
    return markdown(rows)


def local_midnight(data: MeasuredData) -> dt.datetime:
    start = _midnight(data)
    utc = pd.Timestamp(data.times[start]).tz_localize("UTC")
    return utc.tz_convert(data.zone).to_pydatetime().replace(tzinfo=None)


def virtual_twinhouse_file(study: Study, truth: dict[str, float], seed: int, path: Path) -> Path:
    """The Twin House file with the built-in wall's flux at ``truth`` in place of the measured.

    The wall runs on the file's 10-minute clock under the measured surface
    temperatures; column 15 (inside flux) becomes its flux plus white noise of SD
    0.2 W/m², column 16 (the held-out temperature inside the wall) its temperature.
    """
    lines = TWINHOUSE_FILE.read_text(encoding="utf-8").splitlines()
    table = np.loadtxt(lines[2:])
    simulator = build_simulator(study)
    step = float(table[1, 0] - table[0, 0])
    forcing = Forcing(step, {"temp_surf_out": table[:, 18], "temp_surf_in": table[:, 14]})
    out = simulator.simulate({**nominal_parameters(study), **truth}, forcing)
    rng = np.random.default_rng(seed)
    table[:, 15] = out["heat_flux_in"] + rng.normal(0.0, 0.2, table.shape[0])
    table[:, 16] = out["temp_interface_2"]
    path.parent.mkdir(parents=True, exist_ok=True)
    body = "\n".join(" ".join(f"{v:.9g}" for v in row) for row in table)
    path.write_text("\n".join(lines[:2]) + "\n" + body + "\n", encoding="utf-8")
    return path


def cut_study(
    example: str, folder: Path, end: dt.datetime, per_day: int, file: Path | None
) -> Path:
    """The example in ``folder``, its record ending at ``end`` (local), one test day."""
    copy_example(example, folder, force=True)
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    if file is not None:
        line = 'file = "data/validationdataN2Exp1.txt"'
        text = text.replace(line, f"file = {file.as_posix()!r}")
    text = text.replace("[data]\n", f'[data]\nend = "{end.isoformat()}"\n', 1)
    text, found = re.subn(r"(?m)^test_(samples|fraction) = .*$", f"test_samples = {per_day}", text)
    if found != 1:
        raise SystemExit(f"the {example} example changed: no single test window line")
    cut = text.index("[calibration]")
    rest = text[cut + len("[calibration]") :]
    following = re.search(r"(?m)^\[", rest)
    text = text[:cut] + (rest[following.start() :] if following else "") + BAYES_SIZES
    path.write_text(text, encoding="utf-8")
    return folder


def bayes_rows(
    example: str, days: list[int], out: Path, virtual: int | None = None
) -> list[dict[str, object]]:
    """The derived U's 95 % interval after ``days`` training days, with the ISO U.

    ``virtual = i``: the twinhouse example on the virtual Twin House wall ``i``
    (1-based, the truths of the ``twinhouse-virtual`` set at ``--truths 10``).
    """
    study = wall_study() if example == "wall" else twinhouse_study()
    if study is None:
        return []
    simulator = build_simulator(study)
    nominal = nominal_parameters(study)
    file, label = (None, example) if example == "wall" else (TWINHOUSE_FILE, example)
    if example == "wall":
        reference = _u(simulator, {**nominal, **WALL_TRUTH})
    elif virtual is None:
        reference = _u(simulator, nominal)  # the catalogue U: no truth
    else:
        physical = ["k_brick", "c_brick", "k_eps", "c_plaster_in"]
        truth = truths(study, VIRTUAL_TRUTHS, physical)[virtual - 1]
        label = f"twinhouse virtual {virtual}"
        file = virtual_twinhouse_file(study, truth, SEED + virtual, out / f"virtual-{virtual}.txt")
        study = twinhouse_study(file)
        assert study is not None
        reference = _u(simulator, {**nominal, **truth})
    data = load_measured(study)
    am = _analyse(data, data.outputs["heat_flux_in"])
    per_day = round(86400.0 / data.step)
    warmup = round(study.periods.warmup.total_seconds() / 86400.0)
    midnight = local_midnight(data)
    rows: list[dict[str, object]] = []
    for d in days:
        end = midnight + dt.timedelta(days=warmup + d + 1)
        folder = cut_study(example, out / f"{label.replace(' ', '-')}-{d}d", end, per_day, file)
        t0 = time.perf_counter()
        res = run(load_study(folder), until="calibrate", options=Options())
        seconds = time.perf_counter() - t0
        assert res.posterior is not None
        u = res.posterior.summary().loc["U_value"]
        mean, lower, upper = float(u["mean"]), float(u["lower"]), float(u["upper"])
        record = warmup + d  # whole days from the first local midnight to the test day
        iso = float(am.u[record - 1]) if record <= am.days[-1] else float("nan")
        rows.append(
            {
                "wall": label,
                "train_days": res.context.measured.layout.m_star,
                "record_days": record,
                "U_ref": round(reference, 4),
                "U_mean": round(mean, 4),
                "U_95": f"[{lower:.4f}, {upper:.4f}]",
                "holds_ref": bool(lower <= reference <= upper),
                "width_%": round(100 * (upper - lower) / reference, 1),
                "U_iso": round(iso, 4),
                "iso_err_%": round(100 * (iso / reference - 1.0), 1),
                "iso_conv": bool(am.converged[record - 1]) if record <= am.days[-1] else "-",
                "U_rhat": round(float(u["r_hat"]), 3),
                "U_ess": round(float(u["ess_bulk"])),
                "warnings": len(res.posterior.warnings),
                "seconds": round(seconds),
            }
        )
        print(markdown(rows[-1:]), flush=True)
    return rows


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=10, help="virtual walls per set")
    parser.add_argument(
        "--set",
        choices=("wall", "twinhouse-virtual", "twinhouse"),
        action="append",
        help="which walls (default: all three sets)",
    )
    parser.add_argument("--curve", action="store_true", help="print the measured wall's days")
    parser.add_argument(
        "--bayes", type=int, nargs="+", metavar="D", help="calibrate on D training days"
    )
    parser.add_argument(
        "--bayes-virtual",
        type=int,
        nargs="+",
        default=[],
        metavar="I",
        help="with --bayes: also the virtual Twin House walls I (1-based)",
    )
    parser.add_argument("--out", type=Path, default=REPO / "out" / "iso9869")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    sets = args.set or ["wall", "twinhouse-virtual", "twinhouse"]
    rows = []
    if "wall" in sets:
        rows += [summary(w) for w in virtual_walls(wall_study(), args.truths, 0.007**0.5, "wall")]
    house = twinhouse_study() if {"twinhouse-virtual", "twinhouse"} & set(sets) else None
    if house is not None and "twinhouse-virtual" in sets:
        rows += [summary(w) for w in virtual_walls(house, args.truths, 0.2, "twinhouse virtual")]
    measured = measured_twinhouse(house) if house is not None and "twinhouse" in sets else None
    if measured is not None:
        rows.append(summary(measured))
    print(markdown(rows))
    if measured is not None and args.curve:
        print()
        print(curve(measured))
    if args.bayes:
        bayes: list[dict[str, object]] = []
        for example in ("wall", "twinhouse"):
            if example in sets:
                bayes += bayes_rows(example, sorted(args.bayes), args.out)
        for i in args.bayes_virtual:
            bayes += bayes_rows("twinhouse", sorted(args.bayes), args.out, virtual=i)
        print()
        print(markdown(bayes))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
