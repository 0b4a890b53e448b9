"""Screening runs that cost nothing extra: ``[design] reuse_screening = true``.

A Sobol screening (``[screening] method = "sobol"``, :mod:`bayescal.pipeline.screen`)
runs a Latin hypercube over every parameter of the study, candidates and
calibrated ones. With ``reuse_screening`` those runs join the calibration's
design instead of being thrown away:

* the design is the screening's hypercube (drawn again from the same
  ``[screening]`` settings, so its values are bit for bit those that were run
  and the run cache answers for them: no simulator call) followed by
  ``[design] runs`` new runs, a Latin hypercube over the calibrated parameters
  with every screened-out candidate at its nominal value;
* the emulator's parameter inputs are every parameter the screening varied:
  the calibrated ones and the screened-out candidates. Its ARD length scales
  learn from the screening runs how little the screened-out ones matter;
* the calibration holds the screened-out inputs at their nominal values (fixed
  coordinates of the Metropolis-within-Gibbs sampler,
  :func:`bayescal.calibration.target.hold_theta`), so their "posterior" is the
  nominal value and the calibrated parameters' posterior is the one of the
  model ``run`` always calibrates (screened-out candidates at nominal);
  predictions evaluate the emulator (or run the simulator) there too;
* :func:`nominal_accuracy` measures the emulator where the calibration uses it,
  at the nominal screened-out values: the leave-one-run-out error of the new
  runs, apart from the screening's.

With ``[design] sequential = true`` (:mod:`bayescal.pipeline.seqdesign`) the
first design is that same design (the screening's runs, then ``[design] runs``
new ones; ``runs = 0`` leaves the screening's runs alone), and every batch is
chosen among the draws of a posterior that holds the screened-out inputs at
nominal: its rows are over every emulator input, the screened-out ones at
their nominal values (:func:`at_nominal`). ``max_runs`` counts the screening's
runs, which are not run again.

The simulator is the screening's (every parameter free,
:func:`bayescal.config.build_simulator` with ``screening=True``), so that the
screening runs' cache keys are found; a new run passes the nominal values
explicitly, which is the same model as the one ``run`` holds them at.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from bayescal.config import Study, build_simulator
from bayescal.design import Design, Prior, latin_hypercube
from bayescal.emulator.gp import LooResult
from bayescal.errors import ConfigError
from bayescal.pipeline.keys import derived_seed
from bayescal.runner import RunResults
from bayescal.simulators.base import Simulator
from bayescal.store import screening as screening_store

__all__ = [
    "at_nominal",
    "emulator_priors",
    "held_parameters",
    "nominal_accuracy",
    "reuse_design",
    "run_parameters",
    "screening_design",
    "screening_rows",
    "study_simulator",
]


def screening_design(study: Study) -> Design:
    """The Latin hypercube of ``[screening] method = "sobol"`` over every parameter.

    What ``bayescal screen`` runs; drawn from the study's ``[screening]`` and
    parameters alone, so the same study gives the same values.

    Raises
    ------
    ConfigError
        Fewer than two parameters or fewer runs than the Sobol GP needs.
    """
    section = study.screening
    priors = study.screening_priors()
    k = len(priors)
    if k < 2:
        raise ConfigError(f"screening needs at least two parameters, got {list(priors)}")
    size = section.sobol_runs(k)
    if size < k + 2:
        raise ConfigError(
            f"screening.runs = {size} is too few for {k} parameters: the Sobol method's "
            f"GP needs at least {k + 2} (10 × k = {10 * k} is usual)"
        )
    seed = section.seed if section.seed is not None else derived_seed(study.study.seed, "screen")
    return latin_hypercube(priors, size, seed)


def held_parameters(study: Study) -> dict[str, float]:
    """Screened-out candidate -> its nominal value, where the emulator takes it as an input
    (``reuse_screening``; empty otherwise)."""
    if not study.design.reuse_screening:
        return {}
    return {name: float(study.parameters[name].nominal) for name in study.candidates}


def emulator_priors(study: Study) -> dict[str, Prior]:
    """The emulator's parameter inputs with ``reuse_screening``: every parameter, in study
    order (the screening's prior ranges)."""
    return study.screening_priors()


def study_simulator(study: Study) -> Simulator:
    """The simulator the study's runs are made with: with ``reuse_screening`` the
    screening's (every parameter free: the reused runs' cache keys, and new runs, scenarios
    and other records pass the screened-out ones at their nominal values), else the one
    that holds the candidates at nominal."""
    return build_simulator(study, screening=study.design.reuse_screening)


def run_parameters(study: Study) -> list[str]:
    """The parameters a run of :func:`study_simulator` takes: every one with
    ``reuse_screening``, else the calibrated ones."""
    return list(emulator_priors(study) if study.design.reuse_screening else study.priors())


def _check_screening(study: Study, screening: Design) -> None:
    """That the output folder holds a Sobol screening of this very hypercube."""
    folder = study.root / study.study.output_dir / screening_store.FOLDER
    fix = "run `bayescal screen` first, or set [design] reuse_screening = false"
    try:
        document = screening_store.load_proposal(folder)
    except (OSError, ValueError) as exc:
        raise ConfigError(
            f"design.reuse_screening: {folder} holds no screening to reuse "
            f"({exc.__class__.__name__})",
            hint=fix,
        ) from exc
    if document.get("method") != "sobol":
        raise ConfigError(
            f"design.reuse_screening: the screening in {folder} is a {document.get('method')} "
            "screening, whose runs cannot join the design",
            hint="run `bayescal screen` again with [screening] method = 'sobol'",
        )
    try:
        found = pd.read_csv(folder / screening_store.DESIGN_FILE, index_col="run")
        values = found[list(screening.names)].to_numpy(dtype=float)
    except (OSError, ValueError, KeyError) as exc:
        raise ConfigError(
            f"design.reuse_screening: the screening's design in {folder} cannot be read or "
            f"lacks a parameter of the study ({exc.__class__.__name__})",
            hint="run `bayescal screen` again",
        ) from exc
    if values.shape != screening.values.shape or not np.allclose(
        values, screening.values, rtol=1e-12, atol=0.0
    ):
        raise ConfigError(
            f"design.reuse_screening: the screening in {folder} was run with other settings "
            "([screening] runs or seed, the parameters or their ranges changed since)",
            hint="run `bayescal screen` again",
        )


def reuse_design(study: Study, new: Design) -> Design:
    """The screening's hypercube, then the new runs ``new`` (over the calibrated parameters)
    with every screened-out candidate at its nominal value, over :func:`emulator_priors`.

    Raises
    ------
    ConfigError
        If the output folder holds no Sobol screening of the study's ``[screening]``
        hypercube (none run, a Morris one, or one run with other settings).
    """
    screening = screening_design(study)
    _check_screening(study, screening)
    priors = emulator_priors(study)
    unit = np.zeros((new.runs, len(priors)))
    for j, name in enumerate(priors):
        if name in new.priors:
            unit[:, j] = new.unit[:, list(new.names).index(name)]
    return Design(priors, np.vstack([screening.unit, at_nominal(study, unit)]), seed=new.seed)


def at_nominal(study: Study, unit: np.ndarray) -> np.ndarray:
    """Normalised rows over :func:`emulator_priors` with every screened-out candidate's
    column set to its nominal value's normalised one (what the calibration holds it at).

    The new runs of the design and the sequential design's batches; ``unit`` as it is
    without ``reuse_screening`` (no column is held).

    Parameters
    ----------
    study
        The study.
    unit
        ``(b, t)`` normalised rows, ``t`` the emulator's parameter inputs.
    """
    rows = np.array(unit, dtype=float)
    held = held_parameters(study)
    if not held:
        return rows
    for j, (name, prior) in enumerate(emulator_priors(study).items()):
        if name in held:
            rows[:, j] = float(prior.to_unit(held[name]))
    return rows


def nominal_accuracy(
    loo: LooResult, sims: RunResults, screening_runs: int, outputs: tuple[str, ...]
) -> dict[str, tuple[float, float]]:
    """Output -> leave-one-run-out RMSE of the new runs (screened-out inputs at nominal,
    where the calibration evaluates the emulator) and of the screening runs.

    ``screening_runs``: the design's first rows that are the screening's; the RMSE is
    over each group's successful runs, periods and samples (NaN for an empty group).
    """
    rows = np.asarray(sims.indices)
    new = rows >= screening_runs
    out = {}
    for q, name in enumerate(outputs):
        per_run = loo.rmse_run[:, q]

        def pooled(mask: np.ndarray, per_run: np.ndarray = per_run) -> float:
            return float(np.sqrt(np.mean(per_run[mask] ** 2))) if mask.any() else float("nan")

        out[name] = (pooled(new), pooled(~new))
    return out


def screening_rows(study: Study) -> int:
    """How many of the design's first rows are the screening's (0 without reuse)."""
    if not study.design.reuse_screening:
        return 0
    return screening_design(study).runs
