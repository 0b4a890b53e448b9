"""The stage runner: study file -> design -> ... -> report, resumable.

:func:`run` executes the stages of :mod:`bayescal.pipeline.stages` in order,
writing each stage's artefacts into the study's output folder through
:mod:`bayescal.store` and recording the stage in ``stages.json``
(:class:`bayescal.store.stages.StageLog`). Running again reuses every stage
whose key (:mod:`bayescal.pipeline.keys`) is unchanged and whose files exist,
and says how long it took when it ran; ``from_stage`` forces that stage and
all later ones. The simulation runner additionally caches every finished run,
so a killed ``simulate`` stage resumes where it stopped.

:func:`load_results` reads back what a study's output folder holds, after
whichever stage it stopped.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import time
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.atomic import read_npz
from bayescal.calibration.bounds import bound_warnings
from bayescal.calibration.identifiability import moves_hint
from bayescal.calibration.posterior import Posterior
from bayescal.config import Study
from bayescal.design import Design
from bayescal.discrepancy import Discrepancy
from bayescal.errors import BayescalError, ConfigError, DataError
from bayescal.pipeline.budget import check_budget, estimate_time
from bayescal.pipeline.keys import keys_and_inputs
from bayescal.pipeline.reuse import nominal_accuracy, screening_rows
from bayescal.pipeline.route import check_route
from bayescal.pipeline.seqdesign import sequential_design
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
    nominal_derived,
    nominal_run,
    predict_stage,
    prepare,
    simulate,
)
from bayescal.report.trust import catalogue_verdicts, held_out_outputs
from bayescal.runner import RunResults
from bayescal.store import design as design_store
from bayescal.store import discrepancy as discrepancy_store
from bayescal.store import emulator as emulator_store
from bayescal.store import posterior as posterior_store
from bayescal.store import predictions as predictions_store
from bayescal.store import runs as runs_store
from bayescal.store.folder import OutputLock, is_output_error, output_error
from bayescal.store.stages import STAGES, StageLog

__all__ = ["Results", "file_logger", "load_results", "run", "write_study_report", "writing"]

Say = Callable[[str], None]
#: What reading back a damaged artefact raises (a truncated archive, a netCDF file that
#: is not one, a variable or key missing): the stage is computed again.
UNREADABLE = (BayescalError, OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile)
#: The report page, relative to the output folder.
REPORT_FILE = Path("report") / "report.html"
LOG_FILE = "bayescal.log"


@dataclass
class Results:
    """What a run produced, or what an output folder holds (stages not reached are ``None``)."""

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

    def missing(self) -> tuple[str, ...]:
        """The stages whose result is not here, in stage order (``discrepancy`` only
        where the study enables it)."""
        have = {
            "design": self.design,
            "simulate": self.simulations,
            "emulator": self.emulator,
            "calibrate": self.posterior,
            "discrepancy": self.discrepancy,
            "predict": self.predictions,
            "report": self.report,
        }
        if not self.context.study.discrepancy.enabled:
            have.pop("discrepancy")
        return tuple(stage for stage, value in have.items() if value is None)

    def diagnostic_warnings(self) -> tuple[str, ...]:
        """Every failed MCMC diagnostic of the phases here, each prefixed by its phase.

        The calibration's chains (theta*, the precisions, AR coefficients) and the
        difference process's theta* chains: R-hat above 1.01, bulk or tail ESS
        below 400, stuck chains, too few chains, NUTS divergences. Empty where
        every diagnostic passed (``bayescal run --strict`` exits non-zero otherwise).
        """
        found: list[str] = []
        if self.posterior is not None:
            found += [f"calibration: {w}" for w in self.posterior.warnings]
        if self.discrepancy is not None:
            found += [f"difference process: {w}" for w in self.discrepancy.posterior.warnings]
        return tuple(found)


class _LogFile(logging.FileHandler):
    """A log file that stops writing, quietly, when writing fails (a full disk): the run
    goes on, and its next artefact reports the disk in one line. logging's own
    handler would print a traceback for every record instead."""

    failed = False

    def emit(self, record: logging.LogRecord) -> None:
        if not self.failed:
            super().emit(record)

    def handleError(self, record: logging.LogRecord) -> None:
        self.failed = True


def file_logger(folder: Path) -> logging.Logger:
    """The ``bayescal`` logger, writing to ``folder/bayescal.log`` (appending).

    Raises
    ------
    OSError
        If the log file cannot be opened (the caller reports it in one line).
    """
    logger = logging.getLogger("bayescal.run")
    logger.setLevel(logging.INFO)
    logger.propagate = False
    target = str((folder / LOG_FILE).resolve())
    for handler in list(logger.handlers):
        if getattr(handler, "baseFilename", None) != target or getattr(handler, "failed", True):
            logger.removeHandler(handler)
            with contextlib.suppress(OSError, ValueError):  # a full disk, a closed file
                handler.close()
    if not logger.handlers:
        handler = _LogFile(target, encoding="utf-8")
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
        logger.addHandler(handler)
    return logger


class _Runner:
    """Runs or reuses each stage and records it."""

    def __init__(self, ctx: Context, force_from: str | None, say: Say) -> None:
        self.ctx = ctx
        self.out = ctx.out
        self.log = StageLog.open(self.out)
        self.logger = file_logger(self.out)
        self.keys, self.inputs = keys_and_inputs(ctx)
        self.say = say
        self.reused: list[str] = []
        self.ran: list[str] = []
        self.stale = False
        self.force_from = force_from
        if force_from is not None:
            self.log.forget_from(force_from)

    def reuse(self, stage: str, load: Callable[[], Any] | None = None) -> tuple[bool, Any]:
        """Whether ``stage`` can be reused, and its result read back by ``load``.

        A stage is reused when nothing before it was redone, its key is the
        recorded one, its files are there and whole (their checksums are the
        recorded ones) and ``load`` reads them; a damaged or unreadable file is
        said in one line and the stage runs again.
        """
        ok = not self.stale and self.log.done(stage, self.keys[stage])
        value = None
        if ok and (damaged := self.log.damaged(stage)):
            ok = False
            self._warn(
                f"{stage}: {', '.join(damaged)} damaged (size or checksum differs from when it "
                "was written); computing the stage again"
            )
        elif ok and load is not None:
            try:
                value = load()
            except UNREADABLE as exc:
                ok = False
                reason = exc.one_line() if isinstance(exc, BayescalError) else repr(exc)
                self._warn(
                    f"{stage}: its files cannot be read back ({' '.join(reason.split())[:200]}); "
                    "computing the stage again"
                )
        if ok:
            self.reused.append(stage)
            self._note(f"{stage}: up to date, reused{self._when(stage)}")
        else:
            why = self._why(stage)
            self.stale = True
            self._note(f"{stage}: running" + (f" ({why})" if why else ""))
        return ok, value

    def _why(self, stage: str) -> str:
        """Why ``stage`` runs again (``""`` on its first run, or where a warning said it)."""
        if self.force_from is not None and STAGES.index(stage) >= STAGES.index(self.force_from):
            return f"--from {self.force_from}"
        changed = self.log.changed_inputs(stage, self.keys[stage], self.inputs[stage])
        if changed is None:
            return (
                "its inputs changed; the record of its last run, from an earlier bayescal, "
                "does not say which"
            )
        if changed:
            return f"inputs changed: {', '.join(changed)}"
        if stage not in self.log.records:
            return ""
        if self.stale and self.ran:
            return f"after {self.ran[-1]} ran again"
        if not self.log.finished(stage):
            return "some of its files are missing"
        return ""

    def _warn(self, text: str) -> None:
        self.logger.warning(text)
        self.say(f"warning: {text}")

    def check_snapshots(self, stage: str) -> None:
        """Say in one line, and remove, the MCMC snapshots of ``stage`` that cannot be
        read (their chains start again from the beginning rather than from them)."""
        folder = self.checkpoints(stage)
        if not folder.is_dir():
            return
        for path in sorted(folder.glob("*.npz")):
            try:
                read_npz(path)
            except UNREADABLE:
                path.unlink(missing_ok=True)
                self._warn(
                    f"{stage}: checkpoint {path.relative_to(self.out)} is damaged; its chain "
                    "starts again from the beginning"
                )

    def _when(self, stage: str) -> str:
        """`` (ran 38.2 s on 2026-11-25 10:31)`` from the record, ``""`` if it does not say."""
        last = self.log.last_run(stage)
        if last is None:
            return ""
        on = "" if last.finished is None else f" on {last.finished:%Y-%m-%d %H:%M}"
        return f" (ran {last.seconds:.1f} s{on})"

    def checkpoints(self, stage: str) -> Path:
        """Folder of the MCMC snapshots of ``stage`` (its key in the name)."""
        return self.out / "checkpoints" / f"{stage}-{self.keys[stage][:16]}"

    def finish(self, stage: str, files: list[str], start: float) -> None:
        seconds = time.perf_counter() - start
        self.log.finish(stage, self.keys[stage], files, seconds, self.inputs[stage])
        shutil.rmtree(self.checkpoints(stage), ignore_errors=True)
        self.ran.append(stage)
        self._note(f"{stage}: done in {seconds:.1f} s")

    def _note(self, text: str) -> None:
        self.logger.info(text)
        self.say(text)


def _design(r: _Runner) -> Design:
    path = r.out / design_store.FILE
    ok, found = r.reuse("design", lambda: design_store.load_design(path))
    if ok:
        return found
    start = time.perf_counter()
    if r.ctx.study.design.sequential:
        design, _ = sequential_design(r.ctx, r.keys["design"], r.say)
    else:
        design = make_design(r.ctx)
    if r.ctx.held or r.ctx.study.design.reuse_screening:
        rows = screening_rows(r.ctx.study)
        r._note(
            f"design: the {rows} runs of the Sobol screening, then {design.runs - rows} new "
            f"runs over the {len(r.ctx.study.calibrated)} calibrated parameters (the "
            f"{len(r.ctx.held)} screened-out ones at their nominal values)"
        )
    design_store.save_design(design, path)
    r.finish("design", [design_store.FILE], start)
    return design


def _simulations(r: _Runner, design: Design) -> RunResults:
    ok, found = r.reuse("simulate", lambda: runs_store.load_simulations(r.out, design))
    if ok:
        return found
    start = time.perf_counter()
    sims = simulate(r.ctx, design)
    if sims.damaged:
        first = (Path("simulations") / "runs" / f"{sims.damaged[0]}.npz").as_posix()
        r._warn(
            f"simulate: {len(sims.damaged)} cached run(s) could not be read (e.g. {first}: "
            "truncated or damaged) and were run again"
        )
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
    ok, found = r.reuse("emulator", lambda: _load_emulator(r.ctx, sims))
    if ok:
        return found
    r.check_snapshots("emulator")
    start = time.perf_counter()
    em = build_emulator(r.ctx, sims, r.checkpoints("emulator"))
    emulator_store.save_emulator(
        em.emulator,
        r.out / emulator_store.FILE,
        r.ctx.study.config_hash(),
        parameter_units=_parameter_units(r.ctx),
        inputs=emulator_store.CalibrationInputs(
            em.assembled.w_star, em.assembled.y_star_std, em.assembled.lam_star_prior
        ),
    )
    emulator_store.save_emulator_cv(em.loo, r.out / emulator_store.CV_FILE)
    logs = r.ctx.transforms
    for name, rmse in em.loo.rmse.items():
        scale = f", on the scale of log({name} + floor)" if name in logs else ""
        r.say(
            f"emulator: leave-one-run-out RMSE of {name} {rmse:.4g} "
            f"(output SD {em.loo.output_sd[name]:.4g}{scale}); {em.emulator.basis.p} basis vectors"
        )
    if r.ctx.held:  # where the calibration evaluates it: the screened-out inputs at nominal
        rows = screening_rows(r.ctx.study)
        for name, (new, old) in nominal_accuracy(em.loo, sims, rows, tuple(em.loo.rmse)).items():
            r._note(
                f"emulator: leave-one-run-out RMSE of {name} at the nominal values of the "
                f"{len(r.ctx.held)} screened-out parameters {new:.4g} ({sims.design.runs - rows} "
                f"new runs), at the {rows} reused screening runs {old:.4g}"
            )
    r.finish("emulator", [emulator_store.FILE, emulator_store.CV_FILE], start)
    return em


def _calibration(r: _Runner, em: EmulatorResult) -> Posterior:
    ok, found = r.reuse(
        "calibrate", lambda: posterior_store.load_posterior(r.out / posterior_store.FILE)
    )
    if ok:
        return found
    r.check_snapshots("calibrate")
    start = time.perf_counter()
    post = calibrate_stage(r.ctx, em, checkpoint_dir=r.checkpoints("calibrate"))
    posterior_store.save_posterior(post, r.out / posterior_store.FILE, r.ctx.study.config_hash())
    posterior_store.save_posterior_summary(post, r.out / posterior_store.SUMMARY_FILE)
    _say_calibration_length(r, post)
    for w in post.warnings:
        r.logger.warning("calibration: %s", w)
        r.say(f"warning: {w}")
    for w in bound_warnings(post.unit_draws, post.priors):
        r.logger.warning("calibration: %s", w)
        r.say(f"WARNING: {w}")
    hint = moves_hint(post) if _gibbs_moves(r.ctx.study) else None
    if hint is not None:
        r.logger.warning("calibration: %s", hint)
        r.say(f"hint: {hint}")
    r.finish("calibrate", [posterior_store.FILE, posterior_store.SUMMARY_FILE], start)
    return post


def _say_calibration_length(r: _Runner, post: Posterior) -> None:
    """How long the chains ran when [calibration] max_samples let them grow; loud when
    they still failed their diagnostics at that length."""
    cal = r.ctx.study.calibration
    if not cal.extends:
        return
    kept = post.draws.shape[1]
    if kept > cal.samples:
        verdict = "every diagnostic passes" if post.diagnostics.ok else "still failing"
        text = f"chains extended from {cal.samples} to {kept} kept draws ({verdict})"
        r.logger.info("calibration: %s", text)
        r.say(f"calibration: {text}")
    if not post.diagnostics.ok:
        text = (
            f"the calibration did NOT converge within [calibration] max_samples = "
            f"{cal.most_samples} kept draws per chain; its intervals are unreliable: raise "
            "max_samples or burn" + (", or try moves = 'joint'" if cal.moves == "gibbs" else "")
        )
        r.logger.warning("calibration: %s", text)
        r.say(f"WARNING: {text}")


def _gibbs_moves(study: Study) -> bool:
    """Whether the calibration moved its coordinates one at a time (``moves = "gibbs"``)."""
    cal = study.calibration
    return cal.sampler == "mwg" and cal.moves == "gibbs"


def _discrepancy(r: _Runner, em: EmulatorResult, post: Posterior) -> Discrepancy | None:
    if not r.ctx.study.discrepancy.enabled:
        if not r.reuse("discrepancy")[0]:
            r.finish("discrepancy", [], time.perf_counter())
        return None
    path = r.out / discrepancy_store.FILE
    ok, found = r.reuse("discrepancy", lambda: discrepancy_store.load_discrepancy(path))
    if ok:
        return found
    start = time.perf_counter()
    disc = discrepancy_stage(r.ctx, em, post, checkpoint_dir=r.checkpoints("discrepancy"))
    assert disc is not None  # enabled above
    discrepancy_store.save_discrepancy(disc, path)
    _say_discrepancy_mixing(r, disc)
    r.finish("discrepancy", [discrepancy_store.FILE], start)
    return disc


def _say_discrepancy_mixing(r: _Runner, disc: Discrepancy) -> None:
    """The phase's length and worst diagnostics; loud when it did not converge."""
    post = disc.posterior
    diag = post.diagnostics
    t = len(post.names)
    chains, kept = post.unit_draws.shape[:2]
    r.say(
        f"discrepancy: {chains} chains x {kept} kept draws, {disc.updates} updates of Delta "
        f"per chain; worst R-hat {np.nanmax(diag.rhat[:t]):.3f}, smallest bulk ESS "
        f"{np.nanmin(diag.ess_bulk[:t]):.0f}, tail ESS {np.nanmin(diag.ess_tail[:t]):.0f}"
    )
    if disc.converged is False:
        text = (
            "the difference-process phase did NOT converge (R-hat <= 1.01 and bulk and tail "
            "ESS >= 400 not reached within [discrepancy] max_samples); its theta* draws and "
            "Delta are unreliable: raise max_samples, or lower update_interval (more updates "
            "of Delta per sweep mix a slow parameter faster)"
        )
        r.logger.warning("discrepancy: %s", text)
        r.say(f"WARNING: {text}")
    for w in diag.warnings:
        r.logger.warning("discrepancy: %s", w)
        r.say(f"warning: {w}")


def _predictions(
    r: _Runner, em: EmulatorResult, post: Posterior, disc: Discrepancy | None
) -> Predictions:
    ok, found = r.reuse("predict", lambda: Predictions(*predictions_store.load_predictions(r.out)))
    if ok:
        return found
    start = time.perf_counter()
    route, centre, off_basis, said = None, None, None, None
    if r.ctx.study.predict.method == "auto":
        check = check_route(r.ctx, em, post)
        said = check.line()
        r._note(said)
        if (centre := check.warning()) is not None:
            r.logger.warning("predict: %s", centre)
            r.say(f"WARNING: {centre}")
        route = check.route
        off_basis = check.off_basis if check.completes else None
    pred = predict_stage(
        r.ctx, em, post, disc, nominal_run(r.ctx), method=route, off_basis=off_basis
    )
    if said is not None:  # kept with the predictions: `show` and the report repeat it
        pred.dataset.attrs["route_check"] = said
    if centre is not None:
        pred.dataset.attrs["route_warning"] = centre
    files = predictions_store.save_predictions(r.out, pred.dataset, pred.metrics)
    held = held_out_outputs(dict(pred.dataset.attrs))
    for verdict in catalogue_verdicts(pred.metrics, held):
        r.logger.info("predict: out of sample: %s", verdict.line())
        if (text := verdict.warning()) is not None:
            r.logger.warning("predict: %s", text)
            r.say(f"WARNING: {text}")
    r.finish("predict", files, start)
    return pred


def _report(r: _Runner, res: Results) -> Path:
    target = r.out / REPORT_FILE
    if r.reuse("report")[0]:
        return target
    start = time.perf_counter()
    path = write_study_report(res)
    r.finish("report", [str(path.relative_to(r.out))], start)
    return path


def write_study_report(res: Results) -> Path:
    """Write the HTML report of a run's results into ``out/report/``.

    Raises
    ------
    ConfigError
        If the emulator, calibrate or predict stage has not run.
    """
    from bayescal.report.study import write_study_report as write

    if res.emulator is None or res.posterior is None or res.predictions is None:
        missing = [s for s in res.missing() if s in ("emulator", "calibrate", "predict")]
        raise ConfigError(
            "the report needs the emulator, calibrate and predict stages; "
            f"not run yet: {', '.join(missing)}",
            hint=f"run `bayescal run {res.context.study.path}` first",
        )
    sims = res.simulations
    design = res.design if res.design is not None else sims.design if sims is not None else None
    if design is None:  # pragma: no cover - the emulator stage needs the design
        raise ConfigError("the report needs the design stage")
    return write(
        res.context.study,
        res.context.measured.layout,
        res.context.out / REPORT_FILE.parent,
        design=design,
        failures=sims.failures if sims is not None else (),
        emulator=res.emulator.emulator,
        loo=res.emulator.loo,
        posterior=res.posterior,
        discrepancy=res.discrepancy,
        predictions=res.predictions.dataset,
        metrics=res.predictions.metrics,
        nominal_derived=nominal_derived(res.context, tuple(res.posterior.names)),
    )


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
        Receives one-line progress notes (default: discarded); a reused stage
        says how long it ran: ``calibrate: up to date, reused (ran 38.2 s on
        2026-11-25 10:31)``.

    Returns
    -------
    Results

    Raises
    ------
    OutputError
        If the output folder is in use by another run (its lock,
        :class:`bayescal.store.folder.OutputLock`), or cannot be written
        (permission, a full or read-only disk, a file in its place): one line
        naming the path; what was completed stays, and a new run resumes.
    """
    for name, value in (("from_stage", from_stage), ("until", until)):
        if value is not None and value not in STAGES:
            raise ConfigError(f"{name} must be one of {', '.join(STAGES)}, got {value!r}")
    if not study.calibrated:
        raise ConfigError(
            "no parameter to calibrate: every [parameters.<name>] table has screen = true",
            hint=f"run `bayescal screen --apply {study.path}` to calibrate the influential "
            "ones, or set screen = false on those to calibrate",
        )
    ctx = prepare(study, options)
    needs = check_budget(study, ctx.measured, ctx.out)  # before any stage allocates
    tell = say or (lambda _: None)
    if study.study.prior_from is not None:
        from bayescal.pipeline.sequential import prior_from_draws

        made = prior_from_draws(study)
        if made is not None:
            tell(made.describe())
    long_run = estimate_time(study, ctx.measured).warning()
    if long_run is not None:
        tell(f"warning: {long_run}")
    with writing(ctx.out, sum(need.disk for need in needs)):
        ctx.out.mkdir(parents=True, exist_ok=True)
        with OutputLock(ctx.out, command="run") as lock:
            if lock.took_over:
                tell(lock.describe_taken_over())
            return _run_stages(ctx, from_stage, until, tell)


@contextlib.contextmanager
def writing(out: Path, disk: float | None = None) -> Iterator[None]:
    """Turn an OSError of writing ``out`` into one :class:`~bayescal.errors.OutputError`.

    Parameters
    ----------
    out
        The output folder.
    disk
        Estimated bytes the study writes in all (for a full disk, what to free). [B]
    """
    try:
        yield
    except OSError as exc:
        if not is_output_error(exc, out):
            raise
        still = None if disk is None else max(0.0, disk - _held(out))
        raise output_error(exc, out, still_needed=still) from exc


def _held(out: Path) -> int:
    total = 0
    if os.path.isdir(out):
        for path in out.rglob("*"):
            with contextlib.suppress(OSError):
                total += path.stat().st_size if path.is_file() else 0
    return total


def _run_stages(ctx: Context, from_stage: str | None, until: str, say: Say) -> Results:
    study = ctx.study
    r = _Runner(ctx, from_stage, say)
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
    """Read back what a study's output folder holds, without running anything.

    The study may have stopped after any stage: the results of the stages
    recorded as finished in ``stages.json`` (with their files there) are read,
    in stage order up to the first one that is not; the others are ``None``
    (:meth:`Results.missing` lists them). A stage forced to run again
    (``--from``) counts as not finished until it has.

    Raises
    ------
    ConfigError
        If not even the design stage has finished.
    DataError
        If a finished stage's file is damaged (its checksum is not the one
        recorded) or cannot be read back: one line naming it; ``bayescal run``
        computes the stage again.
    """
    ctx = prepare(study)
    out = ctx.out
    log = StageLog.open(out)
    res = Results(ctx)
    if not log.finished("design"):
        raise ConfigError(
            f"{out} has no finished calibration (no stage has finished)",
            hint=f"run `bayescal run {study.path}` first",
        )

    def read(stage: str, load: Callable[[], Any]) -> Any:
        hint = f"`bayescal run {study.path}` computes the {stage} stage again"
        damaged = log.damaged(stage)
        if damaged:
            raise DataError(
                f"{out / damaged[0]} is damaged (its size or checksum differs from when it "
                "was written)",
                hint=hint,
            )
        try:
            return load()
        except UNREADABLE as exc:
            reason = exc.one_line() if isinstance(exc, BayescalError) else repr(exc)
            raise DataError(
                f"the files of the {stage} stage in {out} cannot be read back "
                f"({' '.join(reason.split())[:200]})",
                hint=hint,
            ) from exc

    res.design = read("design", lambda: design_store.load_design(out / design_store.FILE))
    if not log.finished("simulate"):
        return res
    design = res.design
    res.simulations = read("simulate", lambda: runs_store.load_simulations(out, design))
    if not log.finished("emulator"):
        return res
    sims = res.simulations
    res.emulator = read("emulator", lambda: _load_emulator(ctx, sims))
    if not log.finished("calibrate"):
        return res
    res.posterior = read(
        "calibrate", lambda: posterior_store.load_posterior(out / posterior_store.FILE)
    )
    if not log.finished("discrepancy"):
        return res
    if study.discrepancy.enabled and (out / discrepancy_store.FILE).is_file():
        res.discrepancy = read(
            "discrepancy", lambda: discrepancy_store.load_discrepancy(out / discrepancy_store.FILE)
        )
    if not log.finished("predict"):
        return res
    res.predictions = read("predict", lambda: Predictions(*predictions_store.load_predictions(out)))
    if log.finished("report") and (out / REPORT_FILE).is_file():
        res.report = out / REPORT_FILE
    return res
