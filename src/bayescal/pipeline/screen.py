"""``bayescal screen``: Morris or Sobol screening of a study's parameters before calibration.

:func:`screen` draws the Morris trajectories (``[screening] method =
"morris"``) or a Latin hypercube of ``[screening] runs`` runs (``"sobol"``,
:func:`bayescal.design.latin_hypercube`) over every parameter of the
study (the candidates marked ``screen = true`` and the calibrated ones, each
over its prior range), runs them through the same cached, resumable runner
and backends as the design (:func:`bayescal.runner.run_design`, cache in
``OUTPUT_DIR/simulations``), reduces each calibrated output to one scalar
over the training periods (``[screening] statistic``), computes the Morris
indices, or the Sobol indices of a GP fitted to the runs, and the proposal
(:mod:`bayescal.screening`), and writes
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
from bayescal.pipeline.reuse import screening_design
from bayescal.pipeline.run import writing
from bayescal.pipeline.stages import Options
from bayescal.report.screening import write_screening_report, write_sobol_report
from bayescal.runner import RunResults, run_design
from bayescal.screening import (
    Q2_WARN,
    MorrisDesign,
    MorrisIndices,
    Proposal,
    SobolIndices,
    morris_design,
    morris_indices,
    propose,
    sobol_indices,
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
        The Morris trajectories (normalised), or the Sobol method's Latin hypercube.
    runs
        The runner's results (successful rows, failures, cached counts).
    statistics
        Output -> the screened scalar of each design row, shape ``(runs,)``, NaN
        where the run failed.
    indices
        Morris or Sobol indices, one per calibrated output.
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
    method
        ``"morris"`` or ``"sobol"``.
    """

    design: MorrisDesign | Design
    runs: RunResults
    statistics: dict[str, np.ndarray]
    indices: tuple[MorrisIndices | SobolIndices, ...]
    proposal: Proposal
    folder: Path
    page: Path
    seconds: float
    applied: tuple[str, ...] = ()
    method: str = "morris"


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
    """Screen a study's parameters by Morris or Sobol indices (see the module notes).

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
        trajectories (Morris) or ``k + 2`` runs (Sobol), or more runs than
        memory or disk allow.
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
    k = len(priors)
    morris: MorrisDesign | None = None
    if section.method == "sobol":
        design = screening_design(study)  # the same values a reused design runs
        size = design.runs
        plan = f"a Latin hypercube of {size} runs (Sobol indices through a GP)"
    else:
        morris = morris_design(list(priors), section.trajectories, section.levels, seed)
        design = Design(priors, morris.unit, seed=seed)
        plan = f"{section.trajectories} Morris trajectories, {morris.runs} runs"
    with writing(out, need.disk), OutputLock(out, command="screen") as lock:
        if lock.took_over:
            note(lock.describe_taken_over())
        note(f"screen: {k} parameters ({len(study.candidates)} candidates), {plan}")
        runs = _run(study, measured, simulator, design, out / "simulations", options)
        result = _write(study, measured, morris, design, seed, runs, out, start, note)
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
    """The screening design's runs, cached with the design's, with the progress bar."""
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
    morris: MorrisDesign | None,
    design: Design,
    seed: int,
    runs: RunResults,
    out: Path,
    start: float,
    note: Say,
) -> ScreeningResult:
    """The indices of each calibrated output, the proposal and their files.

    Morris indices of the trajectories ``morris`` or, where it is ``None``, the
    Sobol indices of a GP fitted to the runs of the Latin hypercube ``design``.
    """
    section = study.screening
    samples = _training_samples(measured)
    statistics = _statistics(study, measured, design, runs, samples)
    folder = out / store.FOLDER
    counts = {"runs": design.runs, "cached": runs.n_cached, "failed": runs.n_failed}

    def summary(first: dict[str, str], own: dict[str, str]) -> dict[str, str]:
        """The page's facts: ``first``, the runs, the method's ``own``, statistic and time."""
        return {
            **first,
            "parameters": f"{len(design.names)} ({len(study.candidates)} candidates)",
            "runs": f"{design.runs} ({runs.n_cached} from the cache, {runs.n_failed} failed)",
            **own,
            "statistic": f"{section.statistic} over {samples.size} training samples",
            "seconds": f"{time.perf_counter() - start:.1f}",
        }

    indices: tuple[MorrisIndices | SobolIndices, ...]
    if morris is not None:
        found = [
            morris_indices(morris, values, output, bootstrap=section.bootstrap, seed=seed + 1 + k)
            for k, (output, values) in enumerate(statistics.items())
        ]
        proposal = propose(found, section.threshold, section.max_parameters)
        facts = summary({}, {"trajectories × levels": f"{section.trajectories} × {section.levels}"})
        store.save_screening(
            folder, morris, design.values, found, proposal, candidates=study.candidates,
            statistic=section.statistic, runs=counts,
        )  # fmt: skip
        page = write_screening_report(
            folder, found, proposal, study_name=study.study.name, candidates=study.candidates,
            statistic=section.statistic, facts=facts,
        )  # fmt: skip
        indices = tuple(found)
    else:
        sobol = _sobol(study, design, statistics, seed, note)
        proposal = propose(sobol, section.threshold, section.max_parameters)
        facts = summary(
            {"method": "Sobol indices of a GP fitted to a Latin hypercube"},
            {
                "GP leave-one-out Q2": ", ".join(f"{ix.output} {ix.q2:.3f}" for ix in sobol),
                "Saltelli base N × GP paths": f"{section.saltelli} × {section.paths}",
            },
        )
        store.save_sobol(
            folder, design, sobol, proposal, candidates=study.candidates,
            statistic=section.statistic, runs=counts,
        )  # fmt: skip
        page = write_sobol_report(
            folder, sobol, proposal, study_name=study.study.name, candidates=study.candidates,
            statistic=section.statistic, facts=facts,
        )  # fmt: skip
        indices = tuple(sobol)
    return ScreeningResult(
        design=design if morris is None else morris,
        runs=runs,
        statistics=statistics,
        indices=indices,
        proposal=proposal,
        folder=folder,
        page=page,
        seconds=time.perf_counter() - start,
        method="sobol" if morris is None else "morris",
    )


def _statistics(
    study: Study, measured: MeasuredData, design: Design, runs: RunResults, samples: np.ndarray
) -> dict[str, np.ndarray]:
    """Output -> the screened scalar of each design row (NaN where the run failed)."""
    statistics = {}
    for output in study.outputs.calibrate:
        values = np.full(design.runs, np.nan)
        values[runs.indices] = screening_statistic(
            runs.outputs[output], measured.outputs[output], samples, study.screening.statistic
        )
        statistics[output] = values
    return statistics


def _sobol(
    study: Study, design: Design, statistics: dict[str, np.ndarray], seed: int, note: Say
) -> list[SobolIndices]:
    """The GP and Sobol indices of each output, with a note where the GP predicts poorly."""
    section = study.screening
    indices = []
    for k, (output, values) in enumerate(statistics.items()):
        found = sobol_indices(
            design.unit, values, design.names, output, base=section.saltelli,
            paths=section.paths, bootstrap=section.bootstrap, seed=seed + 1 + k,
        )  # fmt: skip
        if not found.reliable:
            note(
                f"screen: the GP of {output}'s {section.statistic} predicts the runs left out "
                f"with Q2 = {found.q2:.2f} < {Q2_WARN:g}: its Sobol ranking is unreliable; "
                "raise [screening] runs or use method = 'morris'"
            )
        indices.append(found)
    return indices
