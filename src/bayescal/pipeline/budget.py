"""Memory, disk and time a study will need, estimated before anything is allocated.

Every size a study sets (``[design] runs``, the record's samples and periods,
``[emulator] samples`` and basis size, ``[calibration] chains`` x ``samples``,
``[discrepancy]`` realisations and samples, ``[predict]`` draws and runs,
``[screening] trajectories``) implies arrays in memory and files in the output
folder. :func:`estimate` adds up the largest of them from the validated study
and its measured data, and :func:`check_budget` refuses, in one line naming the
key at fault and the estimate, a study that would not fit: ``bayescal
validate`` calls it, ``bayescal run`` before its first stage and ``bayescal
screen`` (on the screening's part, :func:`screening_need`) before its first
simulation. Where two keys multiply (chains x samples), the message names the
one further above its default, the one most likely mistyped.

The limits are, in this order: ``[runner] max_memory`` / ``max_disk`` of the
study, the environment variables ``BAYESCAL_MAX_MEMORY`` / ``BAYESCAL_MAX_DISK``
(sizes such as ``"64GiB"``: a big machine's or a cluster node's own limits),
else what this machine has: its physical memory (or the container's limit,
whichever is lower) and the free space of the output folder's file system plus
what the output folder already holds (a resumed run rewrites it).

The estimates count float64 arrays and the files bayescal writes; they are
lower bounds of the real peak (Python objects, temporary copies and libraries
come on top) and are meant to catch sizes that are wrong by orders of
magnitude, such as ``runs = 1000000000``.

:func:`estimate_time` gives the order of magnitude of the emulator's and the MCMC
stages' time from a per-sweep cost model (constants timed on the wall example); it
warns, naming the key, past :data:`LONG_RUN`, and refuses nothing.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import ByteSize, TypeAdapter, ValidationError

from bayescal.errors import ConfigError

if TYPE_CHECKING:
    from bayescal.config import Study
    from bayescal.config.base import Section
    from bayescal.data.measured import MeasuredData

__all__ = [
    "DISK_VARIABLE",
    "MEMORY_VARIABLE",
    "Need",
    "TimeEstimate",
    "TimeNeed",
    "check_budget",
    "estimate",
    "estimate_time",
    "format_bytes",
    "format_seconds",
    "machine_memory",
    "screening_need",
]

MEMORY_VARIABLE = "BAYESCAL_MAX_MEMORY"
DISK_VARIABLE = "BAYESCAL_MAX_DISK"
_F = 8  # bytes of a float64
_X_PER_SERIES = 3  # variable inputs per boundary series (its PCA components), a typical count
_FIXED_DISK = 20e6  # report, figures, logs, JSON records [B]


@dataclass(frozen=True)
class Need:
    """What one part of a study needs.

    Attributes
    ----------
    what
        The part (``"simulations"``).
    key
        The study key whose size drives it (``"design.runs"``).
    detail
        How the size arises (``"30 runs × 1644 samples × 1 output"``).
    memory, disk
        Estimated bytes in memory and in the output folder. [B]
    """

    what: str
    key: str
    detail: str
    memory: float
    disk: float


def format_bytes(size: float) -> str:
    """``23.4 GiB``, ``512 B``, ``3.1e+06 TiB``."""
    for unit, scale in (("TiB", 2.0**40), ("GiB", 2.0**30), ("MiB", 2.0**20), ("KiB", 2.0**10)):
        if size >= scale:
            value = size / scale
            return f"{value:.3g} {unit}" if value < 1e4 else f"{value:.2e} {unit}"
    return f"{size:.0f} B"


def _out_of_proportion(*keys: tuple[Section, str, str]) -> str:
    """Of the keys that multiply into one size (``(section, field, "section.field")``),
    the one furthest above its default: where ``chains = 100000000`` makes the
    calibration's draws absurd, the message names ``calibration.chains``, not
    ``calibration.samples``. Ties go to the first."""

    def ratio(item: tuple[Section, str, str]) -> float:
        section, name, _ = item
        usual = type(section).model_fields[name].default
        return float(getattr(section, name)) / float(usual or 1)

    return max(keys, key=ratio)[2]


def screening_need(study: Study, measured: MeasuredData) -> Need:
    """What ``bayescal screen`` needs: ``trajectories x (parameters + 1)`` simulator runs
    (Morris) or ``runs`` (Sobol's Latin hypercube; :mod:`bayescal.pipeline.screen`),
    cached in ``OUTPUT_DIR/simulations`` like the design's, and the tables of
    ``OUTPUT_DIR/screening``."""
    s = study
    k, n = len(s.parameters), int(measured.n)
    outputs_sim = max(len(s.simulator.output_names()), len(s.outputs.calibrate))
    word = "output" if outputs_sim == 1 else "outputs"
    q = len(s.outputs.calibrate)
    if s.screening.method == "sobol":
        runs = s.screening.sobol_runs(k)
        key, what = "screening.runs", f"{runs} runs (Sobol's Latin hypercube)"
    else:
        trajectories = int(s.screening.trajectories)
        runs = trajectories * (k + 1)
        key = "screening.trajectories"
        what = f"{trajectories} trajectories × ({k} parameters + 1) = {runs} runs"
    return Need(
        "screening",
        key,
        f"{what} × {n} samples × {outputs_sim} {word}",
        2.0 * runs * (outputs_sim * n + 2 * k + q) * _F,  # results, design (unit and values)
        runs * (outputs_sim * n * _F + 4096.0) + 3.0 * runs * (k + q) * _F,  # cache, tables
    )


def estimate(study: Study, measured: MeasuredData) -> list[Need]:
    """Memory and disk of each part of ``study`` on its measured record.

    Returns
    -------
    list of Need
        One entry per part, largest-memory first. The screening's part
        (:func:`screening_need`) is counted where the study screens: it has
        candidates (``screen = true``) or a ``[screening]`` section.
    """
    s = study
    t, runs, n = len(s.parameters), int(s.design.runs), int(measured.n)
    outputs_sim = max(len(s.simulator.output_names()), len(s.outputs.calibrate))
    q = len(s.outputs.calibrate)
    lay = measured.layout
    period, m = int(lay.period), int(lay.m_star)
    m_all = m + int(lay.test_starts.size)
    rows = q * period  # N: the stacked within-period axis
    columns = runs * m  # R m*: every run cut into the training periods
    em = s.emulator
    basis = min(em.pca_components or 20, rows, max(columns, 1))
    r = len(s.boundary_conditions) * (em.history_periods + 1) * _X_PER_SERIES
    hyper = basis * (t + r + 1) + 1
    cal = s.calibration
    kept = cal.chains * cal.samples
    d_samples = s.discrepancy_lengths()[1]
    predict = s.predict
    word = "output" if outputs_sim == 1 else "outputs"
    needs = [
        Need("design", "design.runs", f"{runs} runs × {t} parameters", 2.0 * runs * t * _F, 0.0),
        Need(
            "simulations",
            "design.runs",
            f"{runs} runs × {n} samples × {outputs_sim} {word}",
            2.0 * runs * outputs_sim * n * _F,
            2.0 * runs * (outputs_sim * n * _F + 4096.0),  # per-run cache + simulations.npz
        ),
        Need(
            "emulator data",
            "design.runs",
            f"{rows} rows × {runs} runs × {m} periods",
            3.0 * rows * columns * _F,
            (rows + basis) * columns * _F,
        ),
    ]
    if em.algebra == "dense":
        needs.append(
            Need(
                "dense emulator algebra",
                "emulator.algebra",
                f"('dense') ({runs} runs × {m} periods)² per basis vector",
                3.0 * float(columns) ** 2 * _F,
                0.0,
            )
        )
    else:
        pieces = basis * (float(runs) ** 2 + float(m) ** 2 + 2.0 * columns) * _F
        needs.append(
            Need(
                "emulator algebra",
                "design.runs",
                f"{basis} basis vectors × ({runs}² + {m}² + 2 × {runs} × {m})",
                2.0 * pieces,
                pieces,
            )
        )
    emulator_draws = 2.0 * em.samples * hyper * _F
    needs += [
        Need(
            "emulator draws",
            "emulator.samples",
            f"2 chains × {em.samples} samples × {hyper} hyperparameters",
            emulator_draws,
            emulator_draws,
        ),
        Need(
            "calibration draws",
            _out_of_proportion(
                (cal, "samples", "calibration.samples"), (cal, "chains", "calibration.chains")
            ),
            f"{cal.chains} chains × {cal.samples} samples × {t + 4} variables",
            3.0 * kept * (t + 4) * _F,
            3.0 * kept * (t + 4) * _F,  # posterior.nc (twice) and the checkpoints
        ),
    ]
    if s.discrepancy.enabled:
        disc = s.discrepancy
        draws = cal.chains * d_samples * (t + 4 + disc.realisations // 10 + 1)
        samples_key = (
            (cal, "samples", "calibration.samples")
            if disc.samples is None
            else (disc, "samples", "discrepancy.samples")
        )
        needs.append(
            Need(
                "discrepancy",
                _out_of_proportion(
                    (disc, "realisations", "discrepancy.realisations"),
                    samples_key,
                    (cal, "chains", "calibration.chains"),
                ),
                f"{disc.realisations} realisations × {m} periods × {rows} rows, "
                f"{cal.chains} chains × {d_samples} samples",
                (2.0 * disc.realisations * m * rows + draws) * _F,
                (disc.realisations * m_all * rows + draws) * _F,
            )
        )
    if predict.method in ("simulator", "auto"):  # auto: at most the simulator route
        needs.append(
            Need(
                "predictions",
                "predict.runs",
                f"{predict.runs} runs × {n} samples × {outputs_sim} {word}",
                2.0 * predict.runs * outputs_sim * n * _F,
                predict.runs * (outputs_sim * n * _F + 4096.0) + 20.0 * q * n * _F,
            )
        )
    else:
        needs.append(
            Need(
                "predictions",
                "predict.draws",
                f"{predict.draws} draws × {m_all} periods × {rows} rows",
                2.0 * predict.draws * m_all * rows * _F,
                20.0 * q * n * _F,
            )
        )
    if s.candidates or "screening" in s.model_fields_set:
        needs.append(screening_need(s, measured))
    needs.append(Need("report and records", "", "", 0.0, _FIXED_DISK))
    return sorted(needs, key=lambda need: -need.memory)


@dataclass(frozen=True)
class TimeNeed:
    """How long one MCMC or search stage of a study may take, from its sizes.

    Attributes
    ----------
    what
        The stage (``"calibration"``).
    key
        The study key to change where it takes too long (``"calibration.chains"``).
    detail
        How the time arises (``"4 chains × 3000 sweeps × 5 coordinates"``).
    seconds
        The estimate: an order of magnitude (:func:`estimate_time`). [s]
    """

    what: str
    key: str
    detail: str
    seconds: float


@dataclass(frozen=True)
class TimeEstimate:
    """The stages' times (:class:`TimeNeed`) and the simulator runs not estimated."""

    parts: tuple[TimeNeed, ...]
    simulator_runs: int

    @property
    def seconds(self) -> float:
        """The stages' sum. [s]"""
        return sum(part.seconds for part in self.parts)

    def warning(self) -> str | None:
        """A line naming the key to change where the stages take over :data:`LONG_RUN`."""
        if self.seconds <= LONG_RUN:
            return None
        worst = max(self.parts, key=lambda part: part.seconds)
        return (
            f"{worst.key}: the {worst.what} alone may take about {format_seconds(worst.seconds)} "
            f"({worst.detail}); lower {worst.key} unless that is meant"
        )


#: A study whose MCMC and searches take longer than this is warned about. [s]
LONG_RUN = 3600.0
#: The cost model of :func:`estimate_time`, from the wall example (30 runs, 24 periods,
#: 5 basis vectors) timed on a two-core development machine: seconds per coordinate
#: move of a Metropolis-within-Gibbs sweep (emulator hyperparameters, calibration)
#: beyond the linear algebra, the algebra's seconds per flop-like unit, and the gradient
#: search of one basis vector's hyperparameters (training = 'map') at the wall's sizes.
_EMULATOR_MOVE = 3e-4
_CALIBRATION_MOVE = 2.5e-4
_ALGEBRA = 2e-9
_MAP_PER_BASIS = 2.5
_WALL = 30.0**2 + 30.0 * 24.0 + 24.0**2
#: Basis vectors assumed where pca_variance chooses them (the wall example has 5).
_BASIS_GUESS = 5


def format_seconds(seconds: float) -> str:
    """``40 s``, ``12 min``, ``3.5 h``, ``12 days``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.2g} h"
    return f"{seconds / 86400:.3g} days"


def estimate_time(study: Study, measured: MeasuredData) -> TimeEstimate:
    """How long the emulator, the calibration and the difference process may take.

    An order of magnitude, not a forecast: each Metropolis-within-Gibbs sweep costs
    its coordinates times a constant and the linear algebra of the study's sizes
    (``runs³ + periods³`` per emulator move, ``basis × (runs² + runs × periods)``
    per calibration move), the gradient search of the emulator (``training =
    'map'``) a constant per basis vector scaled by ``runs² + runs × periods +
    periods²``; the constants were timed on the wall example. Chains extended
    towards ``max_samples`` take longer; NUTS is costed like Metropolis sweeps. The
    simulator's runs are not timed here (their count is returned): ``bayescal
    simulate`` runs one.
    """
    s = study
    t, runs, q = len(s.calibrated), int(s.design.runs), len(s.outputs.calibrate)
    lay = measured.layout
    m = int(lay.m_star)
    em, cal = s.emulator, s.calibration
    rows = q * int(lay.period)
    basis = max(1, min(em.pca_components or _BASIS_GUESS, rows, runs * m))
    guess = "" if em.pca_components else " (assumed; pca_variance chooses)"
    r = len(s.boundary_conditions) * (em.history_periods + 1) * _X_PER_SERIES
    parts = []
    if em.training == "mcmc":
        hyper = basis * (t + r + 1) + 1
        sweeps = 2 * (em.burn + em.samples)
        move = _EMULATOR_MOVE + _ALGEBRA * (float(runs) ** 3 + float(m) ** 3)
        key = _out_of_proportion((em, "burn", "emulator.burn"), (em, "samples", "emulator.samples"))
        detail = f"2 chains × {sweeps // 2} sweeps × {hyper} hyperparameters{guess}"
        parts.append(TimeNeed("emulator", key, detail, sweeps * hyper * move))
    else:
        size = (float(runs) ** 2 + float(runs) * m + float(m) ** 2) / _WALL
        detail = f"a gradient search per basis vector, {basis}{guess}, {runs} runs × {m} periods"
        parts.append(TimeNeed("emulator", "design.runs", detail, _MAP_PER_BASIS * basis * size))
    errors = s.outputs.errors
    d = t + 1 + q + sum(1 for n in s.outputs.calibrate if n in errors and errors[n].model == "ar1")
    move = _CALIBRATION_MOVE + _ALGEBRA * basis * (float(runs) ** 2 + float(runs) * m)
    sweeps = cal.burn + cal.samples
    key = _out_of_proportion(
        (cal, "chains", "calibration.chains"),
        (cal, "burn", "calibration.burn"),
        (cal, "samples", "calibration.samples"),
    )
    detail = f"{cal.chains} chains × {sweeps} sweeps × {d} coordinates"
    parts.append(TimeNeed("calibration", key, detail, cal.chains * sweeps * d * move))
    if s.discrepancy.enabled:
        burn, samples, _ = s.discrepancy_lengths()
        detail = f"{cal.chains} chains × {burn + samples} sweeps × {d} coordinates"
        seconds = cal.chains * (burn + samples) * d * move
        parts.append(TimeNeed("difference process", key, detail, seconds))
    simulator = runs + (s.predict.runs if s.predict.method in ("simulator", "auto") else 0)
    return TimeEstimate(tuple(parts), simulator)


def machine_memory() -> int | None:
    """Physical memory of this machine, or its container's limit where lower. [B]"""
    limits = []
    with contextlib.suppress(AttributeError, OSError, ValueError):  # not POSIX
        limits.append(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text(encoding="ascii").strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 2**60:  # "max" or a huge number: no limit
            limits.append(int(text))
    return min(limits) if limits else None


def _free_disk(folder: Path) -> tuple[int | None, int]:
    """Free bytes on the file system of ``folder`` (its nearest existing parent), and the
    bytes ``folder`` holds already."""
    probe = folder
    while not os.path.exists(probe) and probe != probe.parent:  # no OSError (too long)
        probe = probe.parent
    try:
        free: int | None = shutil.disk_usage(probe).free
    except OSError:
        free = None
    held = 0
    if os.path.isdir(folder):
        for path in folder.rglob("*"):
            with contextlib.suppress(OSError):
                held += path.stat().st_size if path.is_file() else 0
    return free, held


def _limit(given: int | None, variable: str, key: str) -> tuple[int | None, str]:
    """The limit set by the study or the environment variable, and where it comes from."""
    if given is not None:
        return int(given), f"[runner] {key}"
    text = os.environ.get(variable)
    if text:
        try:
            return int(TypeAdapter(ByteSize).validate_python(text.strip())), variable
        except ValidationError:
            raise ConfigError(
                f"{variable}={text!r} is not a size",
                hint=f"write it like '64GiB' or '500GB', e.g. {variable}=64GiB",
            ) from None
    return None, ""


def check_budget(
    study: Study,
    measured: MeasuredData,
    out: Path | None = None,
    *,
    needs: Sequence[Need] | None = None,
) -> list[Need]:
    """Refuse a study whose estimated memory or disk exceeds the limits.

    Parameters
    ----------
    study
        A validated study.
    measured
        Its measured data (the record's length and periods size the arrays).
    out
        The output folder (its file system's free space is the disk limit);
        ``study.root / study.study.output_dir`` when omitted.
    needs
        The parts to check (``bayescal screen``: :func:`screening_need` only);
        :func:`estimate` of the whole study when omitted.

    Returns
    -------
    list of Need
        The estimates (:func:`estimate`).

    Raises
    ------
    ConfigError
        One line: the key at fault and its value, the estimate, the limit, and
        how to raise it.
    """
    needs = estimate(study, measured) if needs is None else list(needs)
    folder = out if out is not None else study.root / study.study.output_dir
    memory = sum(need.memory for need in needs)
    limit, origin = _limit(study.runner.max_memory, MEMORY_VARIABLE, "max_memory")
    if limit is None:
        limit, origin = machine_memory(), "this machine"
    if limit is not None and memory > limit:
        setting = (
            f"raise {origin}"
            if origin != "this machine"
            else f"set [runner] max_memory (or {MEMORY_VARIABLE}) where a bigger machine runs it"
        )
        raise _error(
            study, needs, "memory", memory, f"the {format_bytes(limit)} of {origin}", setting
        )
    disk = sum(need.disk for need in needs)
    limit, origin = _limit(study.runner.max_disk, DISK_VARIABLE, "max_disk")
    text = f"the {format_bytes(limit or 0)} of {origin}"
    setting = f"raise {origin}"
    if limit is None:
        free, held = _free_disk(folder)
        limit = None if free is None else free + held
        text = f"the {format_bytes(limit or 0)} free for {folder}"
        setting = (
            f"free space on that disk, or set study.output_dir to a bigger one ([runner] "
            f"max_disk or {DISK_VARIABLE} set the limit by hand)"
        )
    if limit is not None and disk > limit:
        raise _error(study, needs, "disk", disk, text, setting)
    return needs


def _error(
    study: Study, needs: list[Need], kind: str, total: float, limit: str, setting: str
) -> ConfigError:
    """``design.runs = 1000000000: the study needs about ... of memory (...), more than ...``."""
    value = (lambda need: need.memory) if kind == "memory" else (lambda need: need.disk)
    worst = max((need for need in needs if need.key), key=value)
    parts = [
        f"{need.what} {format_bytes(value(need))}" + (f": {need.detail}" if need is worst else "")
        for need in sorted(needs, key=lambda need: -value(need))[:3]
        if value(need) > 0
    ]
    section, key = worst.key.split(".")
    shown = getattr(getattr(study, section), key)
    return ConfigError(
        f"{worst.key} = {shown!r}: the study needs about {format_bytes(total)} of {kind} "
        f"({'; '.join(parts)}), more than {limit}; lower {worst.key}, or {setting}",
        source=str(study.path),
    )
