"""``bayescal update STUDY``: newly arrived data added to a finished calibration.

Each update is a study of its own, written beside the study file, whose prior is
the previous posterior (``[study] prior_from``, :mod:`bayescal.pipeline.sequential`).
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import tomli_w

from bayescal.clock import format_duration, local_time_problem, local_to_utc
from bayescal.config import Study, load_study
from bayescal.errors import ConfigError, DataError
from bayescal.store import posterior as posterior_store
from bayescal.store.stages import StageLog

__all__ = [
    "HISTORY_FILE",
    "UPDATE_PATTERN",
    "WARMUPS",
    "Update",
    "reuse_runs",
    "runs_line",
    "update",
    "update_files",
]

#: Update study files beside the study's own: ``update-001.toml``, ``update-002.toml``, ...
UPDATE_PATTERN = "update-{:03d}.toml"
#: The history of the posterior over the updates, in the study's output folder.
HISTORY_FILE = "update-history.csv"


@dataclass(frozen=True)
class Update:
    """What ``bayescal update`` made: the update's study and the history of the posterior."""

    study: Study
    previous: Study
    history: pd.DataFrame
    files: dict[str, Path]


def update_files(study: Study) -> list[Path]:
    """The update study files of ``study``, in order."""
    assert study.path is not None  # a loaded study has its file
    root = Path(study.path).parent
    found = []
    k = 1
    while (root / UPDATE_PATTERN.format(k)).is_file():
        found.append(root / UPDATE_PATTERN.format(k))
        k += 1
    return found


def _finished(study: Study) -> bool:
    out = study.root / study.study.output_dir
    return StageLog.open(out).finished("calibrate") and (out / posterior_store.FILE).is_file()


def _local(instant: np.datetime64, zone: Any) -> str:
    """A UTC clock instant as the study's local time text (data.start / data.end), with
    its UTC offset in the hour that the clocks repeat (the local time names two instants)."""
    local = pd.Timestamp(instant).tz_localize("UTC").tz_convert(zone)
    text = local.strftime("%Y-%m-%dT%H:%M:%S")
    return text if local_time_problem(local.tz_localize(None), zone) is None else local.isoformat()


#: What every update says: a chain of updates is one calibration on every day only where
#: the model does not err (docs/validation/case-studies-log.md, #update-warmup).
JOINT_NOTE = (
    "each update fits its error model to its own days, so where the model errs a chain of "
    "updates is narrower than one calibration on all the days (on the Twin House up to "
    "2.2 SD apart and 3-65 % narrower); run the study on every day before relying on these "
    "intervals"
)
#: ``warmup`` of :func:`update`: the record from the first study's start, or the study's
#: own warm-up before the previous test window.
WARMUPS = ("all", "study")


def _update_raw(
    previous: Study,
    base: Study,
    k: int,
    data: Path | None,
    end: pd.Timestamp | None,
    warmup: str | pd.Timedelta = "study",
) -> dict[str, Any]:
    """The study dictionary of update ``k``: the previous study's, trained from its test
    window (``[periods] train_from``) to ``end``, its record starting ``warmup`` before
    that (:func:`update`), with the previous posterior as prior.

    Raises
    ------
    ConfigError
        ``warmup`` shorter than the study's own warm-up, or not a multiple of the
        data step.
    """
    from bayescal.data.measured import load_measured

    measured = load_measured(previous)
    layout = measured.layout
    step = pd.Timedelta(measured.step, "s")
    # where the previous training ended: the first test period (which reaches back
    # before the test window where that does not start on the period grid), else the
    # record's end
    if layout.test_starts.size:
        first = pd.Timestamp(measured.times[int(layout.test_starts[0])])
    else:
        first = pd.Timestamp(measured.times[-1]) + step
    own = pd.Timedelta(previous.periods.warmup)
    if warmup == "all":
        span = max(first - pd.Timestamp(load_measured(base).times[0]), own)
    elif warmup == "study":
        span = own
    else:
        span = pd.Timedelta(warmup)
        if span < own or span % step != pd.Timedelta(0):
            raise ConfigError(
                f"--warmup {format_duration(span)} must be a multiple of the data step "
                f"({format_duration(step)}) and at least the study's warm-up "
                f"({format_duration(own)})",
                hint=f"e.g. --warmup {format_duration(3 * own)}, or --warmup all",
            )
    start_utc = first - span
    assert previous.path is not None
    raw = tomllib.loads(Path(previous.path).read_text(encoding="utf-8"))
    section = raw.setdefault("data", {})
    if data is not None:
        section["file"] = str(Path(data).expanduser().resolve())
    zone = measured.zone
    section["start"] = _local(start_utc.to_datetime64(), zone)
    if end is not None:
        section["end"] = end.isoformat() if end.tz is not None else f"{end:%Y-%m-%dT%H:%M:%S}"
    else:
        section.pop("end", None)

    def utc(value: Any, what: str) -> pd.Timestamp:  # local times compared as instants
        return local_to_utc(pd.Timestamp(value), zone, what)

    begin = start_utc.tz_localize("UTC")
    stop = None if end is None else utc(end, "--to")
    # the first study's exclusions too: an update made with a shorter warm-up dropped
    # the early ones, which a longer warm-up simulates again
    base_data = tomllib.loads(Path(base.path or "").read_text(encoding="utf-8")).get("data", {})
    same_file = data is None and base_data.get("file") == section.get("file")
    windows = (base_data.get("exclude", []) if same_file else []) + section.get("exclude", [])
    section["exclude"] = [
        w
        for i, w in enumerate(windows)
        if w not in windows[:i]
        and utc(w["end"], "data.exclude end") > begin
        and (stop is None or utc(w["start"], "data.exclude start") < stop)
    ]
    if not section["exclude"]:
        section.pop("exclude")
    periods = raw.setdefault("periods", {})
    periods["train_from"] = _local(first.to_datetime64(), zone)
    meta = raw.setdefault("study", {})
    meta["prior_from"] = Path(previous.path).name
    base_raw = tomllib.loads(Path(base.path or "").read_text(encoding="utf-8")).get("study", {})
    meta["output_dir"] = f"{base_raw.get('output_dir', 'out')}/update-{k:03d}"
    meta["name"] = f"{base.study.name} (update {k})"
    return raw


def runs_line(previous: Study, changed: Study) -> str:
    """One line: whether the previous study's simulator runs serve the update.

    A run is cached by the simulator, its parameter values and the boundary
    conditions it was driven by (:func:`bayescal.runner.run_key`), and a study's
    boundary conditions are its record, cut by ``data.start`` and ``data.end``:
    an update ends later (and, with a warm-up shorter than the record before the
    previous test window, starts later), so its runs are made again. Were the two
    forcings the same (same simulator, same boundary conditions), the update's run
    cache would find the
    previous runs once they are linked into its output folder
    (:func:`reuse_runs`).
    """
    from bayescal.data.measured import load_measured
    from bayescal.runner import forcing_fingerprint

    before = load_measured(previous).forcing
    after = load_measured(changed).forcing
    if forcing_fingerprint(before) == forcing_fingerprint(after):
        source = previous.root / previous.study.output_dir / "simulations"
        linked = reuse_runs(source, changed.root / changed.study.output_dir / "simulations")
        return f"runs: reused {linked} from {source}"
    day = 86400.0
    more = (_end(after) - _end(before)) / day
    later = float((after.start - before.start) / np.timedelta64(1, "s")) / day
    line = f"runs: re-simulated: the boundary conditions now cover {more:g} more days"
    if later > 0:
        line += f" and start {later:g} days later"
    return line + " (runs are cached by the boundary conditions they were driven by)"


def reuse_runs(source: Path, target: Path) -> int:
    """Hard-link (else copy) the cached runs ``source/runs/*.npz`` into ``target/runs``.

    A run is found by its key (simulator, boundary conditions, parameter
    values), so a linked run serves only a study that would have made it the
    same; a run already there is kept. Returns how many runs ``target`` now
    shares with ``source``.
    """
    import os
    import shutil

    runs = sorted((source / "runs").glob("*.npz"))
    if runs:
        (target / "runs").mkdir(parents=True, exist_ok=True)
    for run in runs:
        there = target / "runs" / run.name
        if there.exists():
            continue
        try:
            os.link(run, there)
        except OSError:
            shutil.copy2(run, there)
    return len(runs)


def _end(forcing: Any) -> float:
    """The end of a forcing, in seconds of the UTC clock."""
    start = float(np.asarray(forcing.start, dtype="datetime64[s]").astype(np.int64))
    n = len(next(iter(forcing.series.values())))
    return start + n * float(forcing.step)


def _history_row(study: Study, label: str, measured: Any = None) -> dict[str, Any]:
    """One row of the history: the step's training days and its parameters' and derived
    quantities' means and 95 % intervals, read from the run's ``posterior-summary.csv``
    (the posterior itself only where that file is missing). ``measured``: the step's
    measured data where the caller holds them (else read again)."""
    from bayescal.data.measured import load_measured

    out = study.root / study.study.output_dir
    summary = out / posterior_store.SUMMARY_FILE
    posterior = out / posterior_store.FILE
    if summary.is_file() and summary.stat().st_mtime_ns >= posterior.stat().st_mtime_ns:
        table = pd.read_csv(summary, index_col=0)
        names = list(posterior_store.posterior_quantities(posterior))
    else:
        post = posterior_store.load_posterior(posterior)
        table = post.summary()
        names = [*post.names, *post.derived]
    measured = measured if measured is not None else load_measured(study)
    layout = measured.layout
    row: dict[str, Any] = {
        "update": label,
        "study_file": Path(study.path or "").name,
        "first_training": pd.Timestamp(measured.times[int(layout.train_starts[0])]),
        "last_training": pd.Timestamp(
            measured.times[int(layout.train_starts[-1]) + layout.period - 1]
        ),
        "training_periods": layout.m_star,
    }
    for name in names:
        if name in table.index:
            for column in ("mean", "lower", "upper"):
                row[f"{name}_{column}"] = float(np.asarray(table.loc[name, column], dtype=float))
    return row


def _kept_at(path: Path) -> int:
    """When ``path`` was written (ns; 0 where it is missing)."""
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return 0


def _kept_rows(path: Path, k: int) -> dict[str, dict[str, Any]]:
    """The history rows of steps before ``k`` in ``path`` (empty where it cannot be read)."""
    try:
        table = pd.read_csv(path, dtype={"update": str})
    except (OSError, ValueError):
        return {}
    out = {}
    for _, row in table.iterrows():
        label = str(row["update"])
        if label.isdigit() and int(label) < k:
            found = {
                str(c): v for c, v in row.items() if not (isinstance(v, float) and np.isnan(v))
            }
            for column in ("first_training", "last_training"):
                if column in found:
                    found[column] = pd.Timestamp(found[column])
            out[label] = found
    return out


def write_history(study: Study, k: int, measured: Any = None) -> tuple[pd.DataFrame, Path]:
    """Write ``OUTPUT_DIR/update-history.csv`` of ``study`` after its update ``k``.

    The rows of the steps before ``k`` are those the file already holds where their
    posterior is not newer than it (an update never touches an earlier step); the
    others are read from each step's ``posterior-summary.csv`` (:func:`_history_row`).
    ``measured``: update ``k``'s measured data, where the caller holds them.
    """
    from bayescal.atomic import atomic_write_text

    out = study.root / study.study.output_dir
    path = out / HISTORY_FILE
    kept, written_at = _kept_rows(path, k), _kept_at(path)

    def row_of(step: Study, label: str) -> dict[str, Any]:
        saved = kept.get(label)
        posterior = step.root / step.study.output_dir / posterior_store.FILE
        if saved is not None and posterior.stat().st_mtime_ns <= written_at:
            return saved
        return _history_row(step, label)

    rows = [row_of(study, "0")]
    for i, file in enumerate(update_files(study), start=1):
        step = load_study(file)
        if i == k:
            rows.append(_history_row(step, str(i), measured))
        elif _finished(step):
            rows.append(row_of(step, str(i)))
    history = pd.DataFrame(rows)
    return history, atomic_write_text(path, history.to_csv(index=False))


def update(
    study: Study,
    *,
    data: Path | None = None,
    end: pd.Timestamp | None = None,
    options: Any = None,
    say: Callable[[str], None] | None = None,
    warmup: str | pd.Timedelta | None = None,
) -> Update:
    """Add newly arrived data to a finished study: a sequential calibration.

    The latest finished calibration (the study, or its last update) is the
    previous one. Update ``k`` is the study file ``update-00k.toml`` beside the
    study's: the previous study's settings on the record from the previous
    test window (the test window was never trained on) to ``end`` (default: the
    end of the file, ``data`` or the study's own), with ``[study] prior_from``
    the previous study, written into ``OUTPUT_DIR/update-00k``.

    ``warmup`` is how much of the record before the previous test window is
    simulated without being compared (the update's ``[periods] train_from`` is where
    the previous study's training ended, its first test period's start; its
    ``[periods] warmup`` stays the study's):
    ``"all"`` (the default while the data are the first study's file) from its start, so
    that the simulated state at the new days is that of one calibration on
    every day (a heavy wall remembers more than a day: on the 14-day virtual
    wall the study's one-day warm-up moved the update's mean conductivity 1.2
    posterior SD from one calibration on all the days, the whole record 0.1 SD;
    docs/validation/case-studies-log.md); ``"study"`` (the default with
    ``data``, a file that need not hold the earlier days) the study's own
    warm-up; or a duration, a multiple of the data step. A longer warm-up
    lengthens every simulator run of the update. Its simulator runs are made again (runs are
    cached by their boundary conditions, and the record is new: one line says
    so, :func:`runs_line`); its calibration chains start from the previous
    posterior's draws (:func:`bayescal.pipeline.sequential.warm_starts`) with
    the study's burn-in; its stages are cached and resumable like any study's.
    The history of the posterior (means and 95 % intervals of every parameter
    and derived quantity, with the training days of each step) is written to
    ``OUTPUT_DIR/update-history.csv``.

    Raises
    ------
    ConfigError
        The study has no finished calibration, or no new data after it.
    """
    from bayescal.atomic import atomic_write_text
    from bayescal.config.study import study_from_dict
    from bayescal.data.measured import load_measured
    from bayescal.pipeline.run import run as run_pipeline

    tell = say or (lambda _: None)
    if not _finished(study):
        raise ConfigError(
            f"{study.root / study.study.output_dir} holds no finished calibration to update",
            hint=f"run `bayescal run {study.path}` first",
        )
    files = update_files(study)
    previous = study
    for path in files:
        candidate = load_study(path)
        if not _finished(candidate):
            break
        previous = candidate
    # the update after the last finished one (an unfinished one is made again)
    k = 1 if previous is study else files.index(Path(previous.path or "")) + 2
    if warmup is None:  # a file other than the first study's need not hold its days
        other = data is not None or previous.data.file != study.data.file
        warmup = "study" if other else "all"
    raw = _update_raw(previous, study, k, data, end, warmup)
    path = Path(study.path or "").parent / UPDATE_PATTERN.format(k)
    changed = study_from_dict(raw, root=study.root, source=str(path))
    said = warmup if isinstance(warmup, str) else format_duration(warmup)
    try:  # the record the update needs, checked before its file is written
        load_measured(changed)
    except DataError as exc:
        if "before the data cover it" not in exc.message:  # too little new data
            raise ConfigError(
                f"update {k}: the data after {raw['periods']['train_from']} (the previous "
                f"test window) are too short: {exc.message}",
                hint="wait for more data, or give --to or --data",
            ) from None
        raise ConfigError(
            f"update {k} cannot read its record from {raw['data']['start']} (--warmup "
            f"{said}): {exc.message}",
            hint="give --warmup study or a shorter duration, or --data a file that "
            "covers those days",
        ) from None
    text = (
        f"# Update {k} of {Path(study.path or '').name}, written by `bayescal update`: the study's "
        "settings on the\n# newly arrived record, with the previous posterior as prior.\n"
    )
    atomic_write_text(path, text + tomli_w.dumps(raw))
    changed = load_study(path)
    tell(
        f"update {k}: trained from {raw['periods']['train_from']}, simulated from "
        f"{raw['data']['start']} (--warmup {said}), with the posterior of "
        f"{Path(previous.path or '').name} as prior; the calibration chains start from its "
        f"draws; burn-in kept at {changed.calibration.burn} sweeps (a warm start was measured "
        "not to converge sooner: the burn-in adapts the proposal widths)"
    )
    tell(runs_line(previous, changed))
    results = run_pipeline(changed, options=options, say=tell)
    if (caveat := model_error_caveat(results)) is not None:
        tell(f"WARNING: {caveat}")
    else:
        tell(f"note: {JOINT_NOTE}")
    history, file = write_history(study, k, results.context.measured)
    written = {"history": file}
    return Update(changed, previous, history, written)


def model_error_caveat(results: Any) -> str | None:
    """Where the update's data show a model error (the in-likelihood discrepancy's
    verdict, :mod:`bayescal.calibration.modelerror`), why its intervals are not those of
    one calibration on every day; else ``None``."""
    from bayescal.calibration.modelerror import discrepancy_ratios

    if results.posterior is None or results.emulator is None:
        return None
    shown = [
        s.output
        for s in discrepancy_ratios(results.emulator.emulator, results.posterior)
        if s.shown
    ]
    if not shown:
        return None
    return f"the data show a model error ({', '.join(shown)}): {JOINT_NOTE}"
