"""``bayescal screen``: Morris screening of a study's parameters before calibration.

:func:`screen` draws the Morris trajectories over every parameter of the
study (the candidates marked ``screen = true`` and the calibrated ones, each
over its prior range), runs them through the same cached, resumable runner
and backends as the design (:func:`bayescal.runner.run_design`, cache in
``OUTPUT_DIR/simulations``), reduces each calibrated output to one scalar
over the training periods (``[screening] statistic``), computes the Morris
indices and the proposal (:mod:`bayescal.screening`), and writes
``OUTPUT_DIR/screening/`` (:mod:`bayescal.store.screening`,
:mod:`bayescal.report.screening`). ``apply=True`` then marks the proposed
parameters to be calibrated in the study file
(:func:`bayescal.config.edit.set_screen_flags`).

Like ``run``, ``screen`` checks the memory and disk its runs need before the
first one (:func:`bayescal.pipeline.budget.screening_need`), holds the output
folder's lock while it writes there (:class:`bayescal.store.folder.OutputLock`:
a ``run`` or another ``screen`` of the same folder is refused, naming the
holder) and reports an ``OSError`` of the output side in one line
(:func:`bayescal.pipeline.run.writing`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from bayescal.config import Study, build_simulator
from bayescal.config.edit import set_screen_flags
from bayescal.data.measured import MeasuredData, load_measured
from bayescal.design import Design
from bayescal.errors import ConfigError
from bayescal.pipeline.budget import check_budget, screening_need
from bayescal.pipeline.keys import derived_seed
from bayescal.pipeline.run import writing
from bayescal.pipeline.stages import Options
from bayescal.report.screening import write_screening_report
from bayescal.runner import RunResults, run_design
from bayescal.screening import (
    MorrisDesign,
    MorrisIndices,
    Proposal,
    morris_design,
    morris_indices,
    propose,
)
from bayescal.simulators.base import Simulator
from bayescal.store import screening as store
from bayescal.store.folder import OutputLock

__all__ = ["ScreeningResult", "screen", "screening_statistic"]

Say = Callable[[str], None]


@dataclass(frozen=True)
class ScreeningResult:
    """What ``bayescal screen`` computed and wrote.

    Attributes
    ----------
    design
        The Morris trajectories (normalised).
    runs
        The runner's results (successful rows, failures, cached counts).
    statistics
        Output -> the screened scalar of each design row, shape ``(runs,)``, NaN
        where the run failed.
    indices
        Morris indices, one per calibrated output.
    proposal
        The parameters proposed for calibration.
    folder
        ``OUTPUT_DIR/screening``.
    page
        The HTML page.
    seconds
        Wall time of the whole screening. [s]
    applied
        Parameters whose ``screen`` flag ``apply`` changed in the study file.
    """

    design: MorrisDesign
    runs: RunResults
    statistics: dict[str, np.ndarray]
    indices: tuple[MorrisIndices, ...]
    proposal: Proposal
    folder: Path
    page: Path
    seconds: float
    applied: tuple[str, ...] = ()


def screening_statistic(
    simulated: np.ndarray, measured: np.ndarray, samples: np.ndarray, statistic: str
) -> np.ndarray:
    """The screened scalar of each run over the given samples.

    Parameters
    ----------
    simulated
        Runs by samples, shape ``(R, n)``.
    measured
        The measured series, shape ``(n,)``.
    samples
        Indices of the samples scored (the training periods').
    statistic
        ``"mean"``: the mean of the simulated series; ``"rmse"``: its root
        mean squared difference from the measurements (where they are finite).
    """
    sim = np.asarray(simulated, dtype=float)[:, samples]
    if statistic == "mean":
        return np.asarray(sim.mean(axis=1), dtype=float)
    obs = np.asarray(measured, dtype=float)[samples]
    ok = np.isfinite(obs)
    return np.asarray(np.sqrt(np.mean((sim[:, ok] - obs[ok]) ** 2, axis=1)), dtype=float)


def _training_samples(measured: MeasuredData) -> np.ndarray:
    layout = measured.layout
    if not layout.m_star:
        raise ConfigError("no training period: nothing to screen on")
    idx = layout.train_starts[:, None] + np.arange(layout.period)[None, :]
    return np.sort(idx.ravel())


def _runner_options(study: Study, options: Options) -> dict[str, object]:
    runner = study.runner
    return {
        "backend": options.backend or ("dask" if options.scheduler else runner.backend),
        "jobs": options.jobs or runner.jobs,
        "scheduler": options.scheduler or runner.scheduler,
        "timeout": runner.timeout,
        "retries": runner.retries,
    }


def screen(
    study: Study,
    *,
    options: Options | None = None,
    apply: bool = False,
    say: Say | None = None,
) -> ScreeningResult:
    """Screen a study's parameters with Morris elementary effects (see the module notes).

    Parameters
    ----------
    study
        A validated study with at least two parameters.
    options
        Backend, workers and the simulation progress bar (as for ``run``).
    apply
        Set ``screen = false`` on the proposed parameters and ``screen = true``
        on the others in the study file.
    say
        Receives one-line notes.

    Raises
    ------
    ConfigError
        Fewer than two parameters, SALib missing, fewer than two complete
        trajectories, or more trajectories than memory or disk allow.
    OutputError
        If the output folder is in use by another ``run`` or ``screen`` (its
        lock), or cannot be written (permission, a full or read-only disk, a
        file in its place): one line naming the path.
    """
    start = time.perf_counter()
    options = options or Options()
    note = say or (lambda _: None)
    measured = load_measured(study)
    out = study.root / study.study.output_dir
    need = screening_need(study, measured)
    check_budget(study, measured, out, needs=[need])  # before the design is drawn
    section = study.screening
    simulator = build_simulator(study, screening=True)
    priors = study.screening_priors()
    seed = section.seed if section.seed is not None else derived_seed(study.study.seed, "screen")
    morris = morris_design(list(priors), section.trajectories, section.levels, seed)
    design = Design(priors, morris.unit, seed=seed)
    with writing(out, need.disk), OutputLock(out, command="screen") as lock:
        if lock.took_over:
            note(lock.describe_taken_over())
        note(
            f"screen: {len(priors)} parameters ({len(study.candidates)} candidates), "
            f"{section.trajectories} trajectories, {morris.runs} runs"
        )
        runs = _run(study, measured, simulator, design, out / "simulations", options)
        result = _write(study, measured, morris, design, seed, runs, out, start)
    if apply:
        flags = {name: name not in result.proposal.selected for name in study.parameters}
        applied = set_screen_flags(study.path, flags)
        result = replace(result, applied=tuple(applied))
    return replace(result, seconds=time.perf_counter() - start)


def _run(
    study: Study,
    measured: MeasuredData,
    simulator: Simulator,
    design: Design,
    cache: Path,
    options: Options,
) -> RunResults:
    """The Morris design's runs, cached with the design's, with the progress bar."""
    factory = options.progress
    progress, close = factory(design.runs) if factory is not None else (None, lambda: None)
    try:
        return run_design(
            simulator,
            measured.forcing,
            design,
            cache_dir=cache,
            progress=progress,
            **_runner_options(study, options),  # type: ignore[arg-type]
        )
    finally:
        close()


def _write(
    study: Study,
    measured: MeasuredData,
    morris: MorrisDesign,
    design: Design,
    seed: int,
    runs: RunResults,
    out: Path,
    start: float,
) -> ScreeningResult:
    """The Morris indices of each calibrated output, the proposal and their files."""
    section = study.screening
    samples = _training_samples(measured)
    statistics, indices = {}, []
    for k, output in enumerate(study.outputs.calibrate):
        values = np.full(design.runs, np.nan)
        values[runs.indices] = screening_statistic(
            runs.outputs[output], measured.outputs[output], samples, section.statistic
        )
        statistics[output] = values
        indices.append(
            morris_indices(morris, values, output, bootstrap=section.bootstrap, seed=seed + 1 + k)
        )
    proposal = propose(indices, section.threshold, section.max_parameters)
    folder = out / store.FOLDER
    facts = {
        "parameters": f"{len(design.names)} ({len(study.candidates)} candidates)",
        "runs": f"{design.runs} ({runs.n_cached} from the cache, {runs.n_failed} failed)",
        "trajectories × levels": f"{section.trajectories} × {section.levels}",
        "statistic": f"{section.statistic} over {samples.size} training samples",
        "seconds": f"{time.perf_counter() - start:.1f}",
    }
    store.save_screening(
        folder,
        morris,
        design.values,
        indices,
        proposal,
        candidates=study.candidates,
        statistic=section.statistic,
        runs={"runs": design.runs, "cached": runs.n_cached, "failed": runs.n_failed},
    )
    page = write_screening_report(
        folder,
        indices,
        proposal,
        study_name=study.study.name,
        candidates=study.candidates,
        statistic=section.statistic,
        facts=facts,
    )
    return ScreeningResult(
        design=morris,
        runs=runs,
        statistics=statistics,
        indices=tuple(indices),
        proposal=proposal,
        folder=folder,
        page=page,
        seconds=time.perf_counter() - start,
    )
