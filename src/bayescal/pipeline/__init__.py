"""The end-to-end calibration: study file -> design -> ... -> report.

:func:`run` executes the stages of :mod:`bayescal.pipeline.stages` in order,
writing each stage's artefacts into the study's output folder through
:mod:`bayescal.store` (atomically) and recording the stage in ``stages.json``
(:mod:`bayescal.pipeline.state`). Running again reuses every stage whose key
(settings and inputs) is unchanged and whose files exist; ``from_stage``
forces that stage and all later ones. The simulation runner additionally
caches every finished run, so a killed ``simulate`` stage resumes where it
stopped.

Output folder::

    design.csv              Latin hypercube, physical and normalised
    simulations/            per-run cache (runs/*.npz, failures/*.json)
    simulations.npz/.json   the successful runs stacked, the failures listed
    emulator.nc             basis, standardisation, hyperparameters and draws
    emulator-cv.npz         leave-one-run-out cross-validation
    posterior.nc            theta*, lambda, lambda* draws (flat root group + ArviZ groups)
    posterior-summary.csv   the posterior table, with units
    discrepancy.nc          the difference process (when enabled)
    predictions.nc          measured, nominal, calibrated (+ Delta) series
    metrics.csv             fit metrics per output, model and window
    report/report.html      the report (figures in report/figures/)
    checkpoints/            MCMC snapshots of an unfinished stage (removed when it finishes)
    stages.json             what finished, with which key
    bayescal.log            the log of every run
"""

from __future__ import annotations

import dataclasses
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from bayescal.calibration.posterior import Posterior
from bayescal.config import Study
from bayescal.design import Design
from bayescal.errors import ConfigError
from bayescal.metrics import KEY_COLUMNS, metric_columns
from bayescal.pipeline.stages import (
    Context,
    EmulatorResult,
    Options,
    Predictions,
    assemble_runs,
    build_emulator,
    calibrate_stage,
    discrepancy_stage,
    make_design,
    nominal_run,
    predict_stage,
    prepare,
)
from bayescal.pipeline.state import STAGES, StageLog, digest, file_logger
from bayescal.runner import RunResults, forcing_fingerprint, simulator_fingerprint
from bayescal.store import design as design_store
from bayescal.store import discrepancy as discrepancy_store
from bayescal.store import emulator as emulator_store
from bayescal.store import posterior as posterior_store
from bayescal.store import predictions as predictions_store
from bayescal.store import runs as runs_store

if TYPE_CHECKING:
    from bayescal.discrepancy import Discrepancy

__all__ = ["STAGES", "Options", "Results", "run", "stage_keys"]

Say = Callable[[str], None]


@dataclass
class Results:
    """What a run produced (stages not reached are ``None``)."""

    context: Context
    design: Design | None = None
    simulations: RunResults | None = None
    emulator: EmulatorResult | None = None
    posterior: Posterior | None = None
    discrepancy: Discrepancy | None = None
    predictions: Predictions | None = None
    report: Path | None = None
    reused: tuple[str, ...] = ()
    ran: tuple[str, ...] = ()


def _measured_key(ctx: Context) -> str:
    m = ctx.measured
    layout = dataclasses.asdict(m.layout)
    return digest(forcing_fingerprint(m.forcing), dict(m.outputs), layout, m.times)


def stage_keys(ctx: Context) -> dict[str, str]:
    """The key of every stage for the study as it is now."""
    s = ctx.study
    dump = s.model_dump(mode="json")
    keys: dict[str, str] = {}
    keys["design"] = digest("design", dump["parameters"], dump["design"], s.study.seed)
    keys["simulate"] = digest(
        "simulate",
        keys["design"],
        simulator_fingerprint(ctx.simulator),
        forcing_fingerprint(ctx.measured.forcing),
        dump["runner"]["retries"],
        dump["runner"]["timeout"],
    )
    keys["emulator"] = digest(
        "emulator", keys["simulate"], _measured_key(ctx), dump["outputs"], dump["emulator"]
    )
    keys["calibrate"] = digest("calibrate", keys["emulator"], dump["calibration"])
    keys["discrepancy"] = digest("discrepancy", keys["calibrate"], dump["discrepancy"])
    keys["predict"] = digest(
        "predict",
        keys["discrepancy"],
        dump["predict"],
        {n: p.nominal for n, p in s.parameters.items()},
    )
    keys["report"] = digest("report", keys["predict"], s.study.name, s.study.description)
    return keys


# ---------------------------------------------------------------- the stages


class _Runner:
    """Runs or reuses each stage and records it."""

    def __init__(self, ctx: Context, force_from: str | None, say: Say) -> None:
        self.ctx = ctx
        self.out = ctx.out
        self.out.mkdir(parents=True, exist_ok=True)
        self.log = StageLog.open(self.out)
        self.logger = file_logger(self.out)
        self.keys = stage_keys(ctx)
        self.say = say
        self.reused: list[str] = []
        self.ran: list[str] = []
        self.stale = False
        if force_from is not None:
            self.log.forget_from(force_from)

    def reuse(self, stage: str) -> bool:
        """Whether ``stage`` can be read back (and nothing before it was redone)."""
        ok = not self.stale and self.log.done(stage, self.keys[stage])
        if ok:
            self.reused.append(stage)
            self._note(f"{stage}: up to date, reused")
        else:
            self.stale = True
            self._note(f"{stage}: running")
        return ok

    def checkpoints(self, stage: str) -> Path:
        """Folder of the MCMC snapshots of ``stage`` (its key in the name)."""
        return self.out / "checkpoints" / f"{stage}-{self.keys[stage][:16]}"

    def finish(self, stage: str, files: list[str], start: float) -> None:
        seconds = time.perf_counter() - start
        self.log.finish(stage, self.keys[stage], files, seconds)
        shutil.rmtree(self.checkpoints(stage), ignore_errors=True)
        self.ran.append(stage)
        self._note(f"{stage}: done in {seconds:.1f} s")

    def _note(self, text: str) -> None:
        self.logger.info(text)
        self.say(text)


def _design(r: _Runner) -> Design:
    path = r.out / design_store.FILE
    if r.reuse("design"):
        return design_store.load_design(path)
    start = time.perf_counter()
    design = make_design(r.ctx)
    design_store.save_design(design, path)
    r.finish("design", [design_store.FILE], start)
    return design


def _simulations(r: _Runner, design: Design) -> RunResults:
    if r.reuse("simulate"):
        return runs_store.load_simulations(r.out, design)
    start = time.perf_counter()
    from bayescal.pipeline.stages import simulate

    sims = simulate(r.ctx, design)
    for f in sims.failures:
        r.logger.warning("run %d failed (%s): %s", f.index, f.error_type, f.message)
    if sims.failures:
        r.say(f"simulate: {len(sims.failures)} of {design.runs} runs failed and are dropped")
    files = runs_store.save_simulations(r.out, sims)
    r.finish("simulate", files, start)
    return sims


def _parameter_units(ctx: Context) -> list[str]:
    return [prior.unit for prior in ctx.priors.values()]


def _load_emulator(ctx: Context, sims: RunResults) -> EmulatorResult:
    return EmulatorResult(
        assemble_runs(ctx, sims),
        emulator_store.load_emulator(ctx.out / emulator_store.FILE),
        emulator_store.load_emulator_cv(ctx.out / emulator_store.CV_FILE),
    )


def _emulator(r: _Runner, sims: RunResults) -> EmulatorResult:
    if r.reuse("emulator"):
        return _load_emulator(r.ctx, sims)
    start = time.perf_counter()
    em = build_emulator(r.ctx, sims, r.checkpoints("emulator"))
    emulator_store.save_emulator(
        em.emulator,
        r.out / emulator_store.FILE,
        r.ctx.study.config_hash(),
        parameter_units=_parameter_units(r.ctx),
    )
    emulator_store.save_emulator_cv(em.loo, r.out / emulator_store.CV_FILE)
    for name, rmse in em.loo.rmse.items():
        r.say(
            f"emulator: leave-one-run-out RMSE of {name} {rmse:.4g} "
            f"(output SD {em.loo.output_sd[name]:.4g}); {em.emulator.basis.p} basis vectors"
        )
    r.finish("emulator", [emulator_store.FILE, emulator_store.CV_FILE], start)
    return em


def _calibration(r: _Runner, em: EmulatorResult) -> Posterior:
    if r.reuse("calibrate"):
        return posterior_store.load_posterior(r.out / posterior_store.FILE)
    start = time.perf_counter()
    post = calibrate_stage(r.ctx, em, checkpoint_dir=r.checkpoints("calibrate"))
    posterior_store.save_posterior(post, r.out / posterior_store.FILE, r.ctx.study.config_hash())
    posterior_store.save_posterior_summary(post, r.out / posterior_store.SUMMARY_FILE)
    for w in post.warnings:
        r.logger.warning("calibration: %s", w)
        r.say(f"warning: {w}")
    r.finish("calibrate", [posterior_store.FILE, posterior_store.SUMMARY_FILE], start)
    return post


def _discrepancy(r: _Runner, em: EmulatorResult, post: Posterior) -> Discrepancy | None:
    if not r.ctx.study.discrepancy.enabled:
        if not r.reuse("discrepancy"):
            r.finish("discrepancy", [], time.perf_counter())
        return None
    path = r.out / discrepancy_store.FILE
    if r.reuse("discrepancy"):
        return discrepancy_store.load_discrepancy(path)
    start = time.perf_counter()
    disc = discrepancy_stage(r.ctx, em, post)
    assert disc is not None  # enabled above
    discrepancy_store.save_discrepancy(disc, path)
    r.finish("discrepancy", [discrepancy_store.FILE], start)
    return disc


def _predictions(
    r: _Runner, em: EmulatorResult, post: Posterior, disc: Discrepancy | None
) -> Predictions:
    if r.reuse("predict"):
        return Predictions(*predictions_store.load_predictions(r.out))
    start = time.perf_counter()
    pred = predict_stage(r.ctx, em, post, disc, nominal_run(r.ctx))
    files = predictions_store.save_predictions(r.out, pred.dataset, pred.metrics)
    r.finish("predict", files, start)
    return pred


def _report(r: _Runner, res: Results) -> Path:
    target = r.out / "report" / "report.html"
    if r.reuse("report"):
        return target
    start = time.perf_counter()
    path = write_study_report(res)
    r.finish("report", [str(path.relative_to(r.out))], start)
    return path


def write_study_report(res: Results) -> Path:
    """Write the HTML report of a finished run into ``out/report/``."""
    from bayescal.report.html import ReportInputs, write_report

    if res.emulator is None or res.posterior is None or res.predictions is None:
        raise ConfigError("the report needs the emulator, calibrate and predict stages")
    ctx, study = res.context, res.context.study
    disc = res.discrepancy
    warnings = list(res.posterior.warnings)
    sims = res.simulations
    if sims is not None and sims.failures:
        warnings.append(f"{len(sims.failures)} simulator run(s) failed and were dropped")
    inputs = ReportInputs(
        study_name=study.study.name,
        description=study.study.description,
        config_hash=study.config_hash(),
        design=res.design if res.design is not None else sims.design,  # type: ignore[union-attr]
        failures=tuple(sims.failures) if sims is not None else (),
        emulator=res.emulator.emulator,
        loo=res.emulator.loo,
        posterior=res.posterior,
        discrepancy_posterior=None if disc is None else disc.posterior,
        predictions=res.predictions.dataset,
        metrics=res.predictions.metrics,
        delta_correlation=None if disc is None else _delta_correlation(res),
        delta_explained=None if disc is None else dict(disc.explained),
        warnings=tuple(warnings),
        settings=_settings(res),
    )
    return write_report(inputs, ctx.out / "report")


def _delta_correlation(res: Results) -> pd.DataFrame:
    """Pearson correlation of Delta with each boundary condition over the training samples."""
    assert res.predictions is not None
    ds = res.predictions.dataset
    train = ds["window"].values == "train"
    outputs = ds.attrs["outputs"].split(",")
    boundary = [b for b in ds.attrs["boundary"].split(",") if b]
    table = {}
    for o in outputs:
        d = ds[f"{o}_delta"].values[train]
        row = {}
        for b in boundary:
            v = ds[f"bc_{b}"].values[train]
            ok = np.isfinite(d) & np.isfinite(v)
            sd = np.std(d[ok]) * np.std(v[ok]) if ok.sum() > 2 else 0.0
            row[b] = float(np.corrcoef(d[ok], v[ok])[0, 1]) if sd > 0 else float("nan")
        table[o] = row
    return pd.DataFrame(table).T


_SAMPLER_NAMES = {"mwg": "Metropolis-within-Gibbs", "nuts": "NUTS"}


def _settings(res: Results) -> dict[str, object]:
    s = res.context.study
    em = res.emulator
    out: dict[str, object] = {
        "simulator": s.simulator.type,
        "runs (design)": s.design.runs,
        "training periods m*": res.context.measured.layout.m_star,
        "samples per period": res.context.measured.layout.period,
        "test samples": res.context.measured.layout.test,
        "emulator MCMC (burn + kept, 2 chains)": f"{s.emulator.burn} + {s.emulator.samples}",
        "calibration MCMC": f"{_SAMPLER_NAMES[s.calibration.sampler]}, "
        f"{s.calibration.chains} chains x ({s.calibration.burn} + {s.calibration.samples})",
        "algebra": s.emulator.algebra,
        "discrepancy": s.discrepancy.enabled,
        "seed": s.study.seed,
    }
    if s.discrepancy.enabled:
        burn, kept = s.discrepancy_lengths()
        out["discrepancy MCMC"] = (
            f"Metropolis-within-Gibbs with Delta updates, {s.calibration.chains} chains x "
            f"({burn} + {kept})"
        )
    if em is not None:
        out["basis vectors p"] = em.emulator.basis.p
        out["variable inputs x"] = ", ".join(em.emulator.inputs.labels)
    return out


def run(
    study: Study,
    *,
    from_stage: str | None = None,
    until: str = "report",
    options: Options | None = None,
    say: Say | None = None,
) -> Results:
    """Run (or resume) a study's calibration.

    Parameters
    ----------
    study
        A validated study (:func:`bayescal.config.load_study`).
    from_stage
        Force this stage and every later one to run again.
    until
        Last stage to run.
    options
        Backends, workers and progress callbacks (they do not change results).
    say
        Receives one-line progress notes (default: discarded).

    Returns
    -------
    Results
    """
    for name, value in (("from_stage", from_stage), ("until", until)):
        if value is not None and value not in STAGES:
            raise ConfigError(f"{name} must be one of {', '.join(STAGES)}, got {value!r}")
    ctx = prepare(study, options)
    r = _Runner(ctx, from_stage, say or (lambda _: None))
    r.logger.info("bayescal run of %s (config %s)", study.path, study.config_hash()[:12])
    res = Results(ctx)
    last = STAGES.index(until)
    steps: list[tuple[str, Callable[[], None]]] = [
        ("design", lambda: setattr(res, "design", _design(r))),
        ("simulate", lambda: setattr(res, "simulations", _simulations(r, _need(res.design)))),
        ("emulator", lambda: setattr(res, "emulator", _emulator(r, _need(res.simulations)))),
        ("calibrate", lambda: setattr(res, "posterior", _calibration(r, _need(res.emulator)))),
        (
            "discrepancy",
            lambda: setattr(
                res, "discrepancy", _discrepancy(r, _need(res.emulator), _need(res.posterior))
            ),
        ),
        (
            "predict",
            lambda: setattr(
                res,
                "predictions",
                _predictions(r, _need(res.emulator), _need(res.posterior), res.discrepancy),
            ),
        ),
        ("report", lambda: setattr(res, "report", _report(r, res))),
    ]
    for i, (_, step) in enumerate(steps):
        if i > last:
            break
        step()
    res.reused, res.ran = tuple(r.reused), tuple(r.ran)
    return res


def _need(value: Any) -> Any:
    if value is None:  # pragma: no cover - the stages run in order
        raise RuntimeError("a stage ran before the stage it depends on")
    return value


def load_results(study: Study) -> Results:
    """Read back the artefacts of a finished run without running anything.

    Raises
    ------
    ConfigError
        If the study has not been run up to the prediction stage.
    """
    ctx = prepare(study)
    out = ctx.out
    needed = ["design.csv", "simulations.npz", "emulator.nc", "posterior.nc", "predictions.nc"]
    missing = [f for f in needed if not (out / f).exists()]
    if missing:
        raise ConfigError(
            f"{out} has no finished calibration (missing {', '.join(missing)})",
            hint=f"run `bayescal run {study.path}` first",
        )
    design = design_store.load_design(out / design_store.FILE)
    sims = runs_store.load_simulations(out, design)
    em = _load_emulator(ctx, sims)
    disc = None
    if (out / discrepancy_store.FILE).exists() and study.discrepancy.enabled:
        disc = discrepancy_store.load_discrepancy(out / discrepancy_store.FILE)
    pred = Predictions(*predictions_store.load_predictions(out))
    post = posterior_store.load_posterior(out / posterior_store.FILE)
    return Results(ctx, design, sims, em, post, disc, pred)


def describe(res: Results) -> str:
    """A terminal summary: posterior table, diagnostics, metrics."""
    lines = [f"study {res.context.study.study.name!r} -> {res.context.out}"]
    if res.posterior is not None:
        table = res.posterior.summary()
        lines += ["", "posterior (physical units):", table.to_string(float_format="{:.5g}".format)]
        if res.posterior.warnings:
            lines += ["", "diagnostics: NOT all passed"]
            lines += [f"  warning: {w}" for w in res.posterior.warnings]
        else:
            lines += ["", "diagnostics: all passed (R-hat <= 1.01, bulk and tail ESS >= 400)"]
    if res.emulator is not None:
        for name, rmse in res.emulator.loo.rmse.items():
            lines.append(
                f"emulator leave-one-run-out RMSE of {name}: {rmse:.4g} "
                f"(output SD {res.emulator.loo.output_sd[name]:.4g})"
            )
    if res.predictions is not None:
        m = res.predictions.metrics
        cols = [*KEY_COLUMNS, *(c.name for c in metric_columns("show"))]
        lines += [
            "",
            "metrics (max_abs_error is the paper's 'MAE'; CV(RMSE), NMBE in %; guideline14: "
            "CV(RMSE) <= 30 % and |NMBE| <= 10 %, ASHRAE Guideline 14 hourly):",
        ]
        cols = [c for c in cols if c in m.columns]  # older runs lack newer columns
        lines.append(m[cols].to_string(index=False, float_format="{:.4g}".format))
    if res.simulations is not None and res.simulations.failures:
        lines += ["", f"{len(res.simulations.failures)} failed run(s):"]
        lines += [f"  run {f.index}: {f.error_type}: {f.message}" for f in res.simulations.failures]
    return "\n".join(lines)
