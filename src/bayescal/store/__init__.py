"""Artefacts of a study's output folder: one module per artefact, each written atomically.

Every file goes through :mod:`bayescal.atomic` (a temporary file in the same
folder, fsync, rename), so a crash never leaves a half-written artefact under
its final name. What a user may read carries units and descriptions.

Output folder (the module that writes and reads each file)::

    design.csv              Latin hypercube, physical and normalised     store.design
    simulations/            per-run cache (runs/*.npz, failures/*.json)  bayescal.runner
    simulations.npz/.json   the successful runs stacked, the failures    store.runs
    emulator.nc             basis, standardisation, hyperparameters      store.emulator
    emulator-cv.npz         leave-one-run-out cross-validation           store.emulator
    posterior.nc            theta*, lambda, lambda* draws (flat root     store.posterior
                            group + ArviZ groups)
    posterior-summary.csv   mean, sd, interval, R-hat, ESS, unit         store.posterior
    discrepancy.nc          the difference process (when enabled)        store.discrepancy
    predictions.nc          measured, nominal, calibrated (+ Delta)      store.predictions
    metrics.csv             fit metrics per output, model and window     store.predictions
    report/report.html      the report (figures in report/figures/)      bayescal.report
    leave-period-out.npz    per-period scores of bayescal compare        store.crossval
    checkpoints/            MCMC snapshots of an unfinished stage        bayescal.calibration
    stages.json             what finished, with which key, how long,     store.stages
                            each file's size and SHA-256
    bayescal.log            the log of every run                         bayescal.pipeline
    bayescal.lock           held while a run writes the folder           store.folder

A write that fails (permission, a full or read-only disk) becomes one line
naming the path (:func:`bayescal.store.folder.output_error`).
"""

from bayescal.store.design import load_design, save_design
from bayescal.store.discrepancy import load_discrepancy, save_discrepancy
from bayescal.store.emulator import load_emulator, load_emulator_cv, save_emulator, save_emulator_cv
from bayescal.store.posterior import (
    load_posterior,
    posterior_summary,
    save_posterior,
    save_posterior_summary,
)
from bayescal.store.predictions import load_predictions, save_predictions
from bayescal.store.runs import load_simulations, save_simulations
from bayescal.store.stages import STAGES, StageLog

__all__ = [
    "STAGES",
    "StageLog",
    "load_design",
    "load_discrepancy",
    "load_emulator",
    "load_emulator_cv",
    "load_posterior",
    "load_predictions",
    "load_simulations",
    "posterior_summary",
    "save_design",
    "save_discrepancy",
    "save_emulator",
    "save_emulator_cv",
    "save_posterior",
    "save_posterior_summary",
    "save_predictions",
    "save_simulations",
]
