"""Scenarios and their paired differences: ``bayescal predict STUDY --scenario FILE``.

A scenario changes what the calibration did not: fixed inputs of the simulator
(a layer added or replaced, a setpoint, a window: keys of ``[simulator]``) or a
calibrated parameter fixed at a value. The file::

    [baseline]                      # optional: the study as calibrated when omitted
    description = "as built"

    [scenarios.insulated]
    description = "60 mm of EPS outside"
    simulator = { layers = [ ... ] }   # replaces these keys of [simulator]
    set = { k_cb = 0.12 }              # fixes calibrated parameters (inside their priors)

Every scenario and the baseline are simulated at the **same** ``[predict] runs``
posterior draws, on the study's record (after its warm-up) or on ``--data``
(:func:`bayescal.data.measured.load_new_record`). For every output and every
summary over the predicted samples (its mean; its peak; for an energy, its
total) the change ``scenario - baseline`` is computed **draw by draw**: the
parameters' uncertainty that moves both runs alike cancels in the difference,
as it should. Its interval is the central quantiles of the paired differences.
Beside it the *unpaired* interval (the difference of two independent draws,
scenario and baseline drawn apart) shows what ignoring the pairing would
claim, and the ratio of their widths.

What the interval holds: the calibrated parameters' uncertainty (and that of
any parameter left free) propagated through the simulator. The measurement
noise and the model discrepancy are taken as common to both runs and cancel in
the change of a model prediction; a discrepancy that the scenario itself would
change (a retrofit that removes the physics the model lacks) is not in it
(docs/tutorial.md, "Using the calibrated model").
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from bayescal.config import Study
from bayescal.config.study import study_from_dict
from bayescal.data.measured import MeasuredData, load_new_record
from bayescal.errors import BayescalError, ConfigError, SimulatorError
from bayescal.glossary import GLOSSARY
from bayescal.pipeline.newdata import posterior_draws, runs_at
from bayescal.pipeline.reuse import study_simulator

if TYPE_CHECKING:
    from bayescal.pipeline.run import Results

__all__ = [
    "Scenario",
    "ScenarioResult",
    "load_scenarios",
    "run_scenarios",
    "scenario_lines",
    "study_of",
    "write_scenarios",
]

Say = Callable[[str], None]
#: Probabilities of the intervals of the changes.
LEVELS = (0.95, 0.5)


@dataclass(frozen=True)
class Scenario:
    """One scenario: keys of ``[simulator]`` replaced and calibrated parameters fixed."""

    name: str
    description: str = ""
    simulator: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    fixed: Mapping[str, float] = dataclasses.field(default_factory=dict)


@dataclass(frozen=True)
class ScenarioResult:
    """The scenarios' summaries per draw and the table of their changes.

    Attributes
    ----------
    table
        One row per scenario, output and summary: baseline and scenario means,
        the change's mean, its paired and unpaired intervals and the ratio of
        their widths.
    draws
        ``(scenario, output, summary) -> (S,)`` the summary at every draw
        (the baseline under the scenario name ``"baseline"``).
    record
        The record the scenarios were simulated on.
    n_draws
        Posterior draws whose runs succeeded in every scenario.
    """

    table: pd.DataFrame
    draws: Mapping[tuple[str, str, str], np.ndarray]
    record: MeasuredData
    n_draws: int


_KEYS = {"description", "simulator", "set"}


def _scenario(name: str, raw: Any, where: str) -> Scenario:
    if not isinstance(raw, dict):
        raise ConfigError(f"{where} must be a table", hint="e.g. [scenarios.insulated]")
    unknown = sorted(set(raw) - _KEYS)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(unknown)}",
            hint="a scenario has description, simulator = {...} and set = {...}",
        )
    simulator, fixed = raw.get("simulator", {}), raw.get("set", {})
    if not isinstance(simulator, dict) or not isinstance(fixed, dict):
        raise ConfigError(f"{where}: simulator and set must be tables")
    if "type" in simulator:
        raise ConfigError(f"{where}.simulator: a scenario cannot change the simulator's type")
    try:
        values = {str(k): float(v) for k, v in fixed.items()}
    except (TypeError, ValueError):
        raise ConfigError(
            f"{where}.set: values must be numbers", hint="set = { k_cb = 0.12 }"
        ) from None
    return Scenario(name, str(raw.get("description", "")), dict(simulator), values)


def load_scenarios(path: Path) -> tuple[Scenario, list[Scenario]]:
    """The baseline and the scenarios of a scenario file (see the module docstring).

    Raises
    ------
    ConfigError
        A missing or invalid file, no scenario, an unknown key.
    """
    if not path.is_file():
        raise ConfigError(f"{path}: no such scenario file", hint="give --scenario a TOML file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: not a valid TOML file ({exc})") from None
    unknown = sorted(set(raw) - {"baseline", "scenarios"})
    if unknown:
        raise ConfigError(
            f"{path}: unknown table(s) {', '.join(unknown)}",
            hint="a scenario file has [baseline] and [scenarios.NAME] tables",
        )
    tables = raw.get("scenarios", {})
    if not isinstance(tables, dict) or not tables:
        raise ConfigError(
            f"{path}: no scenario", hint="add a [scenarios.NAME] table with simulator or set"
        )
    baseline = _scenario("baseline", raw.get("baseline", {}), "[baseline]")
    scenarios = [_scenario(n, t, f"[scenarios.{n}]") for n, t in tables.items()]
    if "baseline" in tables:
        raise ConfigError(f"{path}: 'baseline' is the reference's name, not a scenario's")
    return baseline, scenarios


def study_of(study: Study, scenario: Scenario, source: str) -> Study:
    """The study with the scenario's ``[simulator]`` keys replaced (validated again)."""
    if not scenario.simulator:
        return study
    if study.path is None:  # pragma: no cover - a loaded study has its file
        raise ConfigError("the study has no file to read its [simulator] from")
    raw = tomllib.loads(Path(study.path).read_text(encoding="utf-8"))
    raw["simulator"] = {**raw.get("simulator", {}), **scenario.simulator}
    where = f"{source} [scenarios.{scenario.name}]"
    changed = study_from_dict(raw, root=study.root, source=where)
    changed._path = study.path
    return changed


def _summaries(name: str, values: np.ndarray) -> dict[str, np.ndarray]:
    """Summaries of ``(S, n)`` runs over the predicted samples, per draw."""
    out = {"mean": values.mean(axis=1), "peak": values.max(axis=1)}
    quantity = GLOSSARY.get(name)
    if quantity is not None and quantity.dimension == "energy":
        out["total"] = values.sum(axis=1)
    return out


def _interval(values: np.ndarray, level: float) -> tuple[float, float]:
    tail = 0.5 * (1.0 - level)
    low, high = np.quantile(values, [tail, 1.0 - tail])
    return float(low), float(high)


def run_scenarios(
    results: Results,
    path: Path,
    *,
    data: Path | None = None,
    start: pd.Timestamp | None = None,
    end: pd.Timestamp | None = None,
    seed: int = 0,
    say: Say | None = None,
) -> ScenarioResult:
    """Simulate the baseline and the scenarios at the same posterior draws and compare.

    Parameters
    ----------
    results
        A calibrated study's results (:func:`bayescal.pipeline.load_results`).
    path
        The scenario file.
    data
        Another record to simulate them on (default: the study's own data file,
        within its ``data.start``/``end``).
    start, end
        Cut the record (local time of the data, end exclusive).
    seed
        Seeds the shuffle of the unpaired interval.
    say
        Receives one-line notes.
    """
    tell = say or (lambda _: None)
    ctx = results.context
    posterior = results.posterior
    if posterior is None:
        raise ConfigError(
            f"{ctx.out} holds no finished calibration",
            hint=f"run `bayescal run {ctx.study.path}` first",
        )
    baseline, scenarios = load_scenarios(path)
    study = ctx.study
    file = data if data is not None else Path(study.data.file)
    if data is None:
        start = start if start is not None else _instant(study.data.start)
        end = end if end is not None else _instant(study.data.end)
    layout = ctx.measured.layout
    anchor = ctx.measured.times[int(layout.train_starts[0])]
    record = load_new_record(study, file, anchor, start=start, end=end)
    priors = ctx.priors
    names = list(posterior.names)
    theta, _ = posterior_draws(posterior, study.predict.runs, {})
    outputs: dict[str, dict[str, np.ndarray]] = {}
    ok: np.ndarray | None = None
    for scenario in (baseline, *scenarios):
        for name, value in scenario.fixed.items():
            if name not in priors or not priors[name].lower <= value <= priors[name].upper:
                raise ConfigError(
                    f"[scenarios.{scenario.name}].set: {name} = {value:g} is not a calibrated "
                    "parameter inside its prior",
                    hint=f"calibrated: {', '.join(priors)}; change fixed inputs with simulator",
                )
        changed = study_of(study, scenario, str(path))
        try:
            simulator = study_simulator(changed)
        except BayescalError as exc:
            raise ConfigError(
                f"[scenarios.{scenario.name}]: {exc.one_line()}",
                hint="the scenario's simulator keys must make a valid [simulator]",
            ) from None
        sc_ctx = dataclasses.replace(ctx, study=changed, simulator=simulator, measured=record)
        th = theta.copy()
        for name, value in scenario.fixed.items():
            th[:, names.index(name)] = value
        tell(f"scenario {scenario.name}: {th.shape[0]} runs at posterior draws")
        runs, rows = runs_at(sc_ctx, th)
        outputs[scenario.name] = {o: _expand(v, rows, th.shape[0]) for o, v in runs.items()}
        full = np.zeros(th.shape[0], dtype=bool)
        full[rows] = True
        ok = full if ok is None else ok & full
    assert ok is not None
    if ok.sum() < 2:
        raise SimulatorError(
            f"only {int(ok.sum())} posterior draws ran in every scenario",
            hint=f"see {ctx.out / 'simulations' / 'failures'}",
        )
    window = slice(record.layout.test_begin, record.layout.n_total)
    draws: dict[tuple[str, str, str], np.ndarray] = {}
    for scenario_name, series in outputs.items():
        for o, values in series.items():
            for summary, column in _summaries(o, values[ok][:, window]).items():
                draws[(scenario_name, o, summary)] = column
    rng = np.random.default_rng(seed)
    rows_out = []
    for scenario in scenarios:
        for (name, o, summary), values in draws.items():
            if name != scenario.name or ("baseline", o, summary) not in draws:
                continue
            base = draws[("baseline", o, summary)]
            paired = values - base
            unpaired = values - rng.permutation(base)
            row: dict[str, Any] = {
                "scenario": scenario.name,
                "output": o,
                "summary": summary,
                "unit": GLOSSARY[o].unit if o in GLOSSARY else "",
                "baseline": float(base.mean()),
                "scenario_value": float(values.mean()),
                "change": float(paired.mean()),
            }
            for level in LEVELS:
                tag = f"{100 * level:g}"
                lo, hi = _interval(paired, level)
                ulo, uhi = _interval(unpaired, level)
                row |= {f"lower{tag}": lo, f"upper{tag}": hi}
                row |= {f"unpaired_lower{tag}": ulo, f"unpaired_upper{tag}": uhi}
            width = row["upper95"] - row["lower95"]
            unpaired_width = row["unpaired_upper95"] - row["unpaired_lower95"]
            row["paired_over_unpaired"] = width / unpaired_width if unpaired_width > 0 else np.nan
            rows_out.append(row)
    return ScenarioResult(pd.DataFrame(rows_out), draws, record, int(ok.sum()))


def _expand(values: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray:
    """Runs of the succeeded ``rows`` on the ``n`` draws (NaN where a run failed)."""
    out = np.full((n, values.shape[1]), np.nan)
    out[rows] = values
    return out


def _instant(value: Any) -> pd.Timestamp | None:
    return None if value is None else pd.Timestamp(value)


def scenario_lines(result: ScenarioResult) -> list[str]:
    """The table of changes as text, one line per scenario, output and summary."""
    lines = [
        f"changes against the baseline at {result.n_draws} posterior draws (paired, draw by "
        "draw; the unpaired interval ignores the pairing):"
    ]
    for _, row in result.table.iterrows():
        lines.append(
            f"  {row['scenario']}: {row['summary']} {row['output']} {row['baseline']:.4g} -> "
            f"{row['scenario_value']:.4g} {row['unit']}, change {row['change']:+.4g} "
            f"[{row['lower95']:+.4g}, {row['upper95']:+.4g}] (95 %), unpaired "
            f"[{row['unpaired_lower95']:+.4g}, {row['unpaired_upper95']:+.4g}]: paired "
            f"{row['paired_over_unpaired']:.2f} of its width"
        )
    return lines


def write_scenarios(result: ScenarioResult, folder: Path) -> dict[str, Path]:
    """Write scenarios.csv (the table) and scenario-draws.csv (every draw's summaries)."""
    from bayescal.atomic import atomic_write_text

    folder.mkdir(parents=True, exist_ok=True)
    table = atomic_write_text(folder / "scenarios.csv", result.table.to_csv(index=False))
    frame = pd.DataFrame({"|".join(k): v for k, v in result.draws.items()})
    draws = atomic_write_text(folder / "scenario-draws.csv", frame.to_csv(index=False))
    return {"table": table, "draws": draws}
