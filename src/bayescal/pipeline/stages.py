"""The stages of a calibration as plain functions, each of the previous result.

::

    ctx = prepare(load_study("study.toml"))
    design = make_design(ctx)
    sims = simulate(ctx, design)
    em = build_emulator(ctx, sims)
    post = calibrate_stage(ctx, em)
    disc = discrepancy_stage(ctx, em, post)          # None unless enabled
    pred = predict_stage(ctx, em, post, disc)

:func:`bayescal.pipeline.run` chains them with caching of finished stages in
the study's output folder; these functions compute and never write, except
the simulation runner's per-run cache.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import xarray as xr

from bayescal.calibration.posterior import Derived, Posterior, calibrate
from bayescal.config import Study, nominal_parameters
from bayescal.config.outputs import OutputError
from bayescal.data.measured import MeasuredData, load_measured
from bayescal.design import Design, Prior, latin_hypercube
from bayescal.emulator.assemble import Assembled, NoiseSpec, assemble
from bayescal.emulator.gp import Emulator, LooResult
from bayescal.emulator.noise import LogLevel
from bayescal.emulator.training import train
from bayescal.errors import ConfigError, SimulatorError
from bayescal.pipeline.completed import completed_band
from bayescal.pipeline.keys import derived_seed
from bayescal.pipeline.predict import (
    Band,
    conditioned_discrepancy,
    delta_series,
    held_out_band,
    merge_bands,
    metrics_table,
    predict_band,
    predictions_dataset,
    simulator_band,
    windows,
)
from bayescal.pipeline.reuse import emulator_priors, held_parameters, reuse_design, study_simulator
from bayescal.pipeline.simnoise import simulator_noise
from bayescal.runner import Progress, RunResults, run_design
from bayescal.simulators.base import Derivable, Simulator

if TYPE_CHECKING:
    from bayescal.discrepancy import Discrepancy

__all__ = [
    "Context",
    "EmulatorResult",
    "Options",
    "Predictions",
    "build_emulator",
    "calibrate_stage",
    "discrepancy_stage",
    "make_design",
    "nominal_derived",
    "predict_stage",
    "prepare",
    "simulate",
]

Tick = Callable[[int], None]


@dataclass(frozen=True)
class Options:
    """Run-time choices that do not change results (so they are not in any stage key).

    Attributes
    ----------
    backend
        Simulation backend; the study's ``[runner] backend`` if ``None``.
    jobs
        Parallel simulation workers; the study's if ``None``.
    scheduler
        Dask scheduler address (implies the dask backend).
    chains_backend
        ``"auto"`` (lockstep groups or worker processes, whichever the target
        suits; the discrepancy phase takes ``"processes"``), ``"processes"``
        (MCMC chains in parallel) or ``"serial"``.
    progress
        Factory of a simulation progress callback: ``total -> (progress, close)``
        (see :func:`bayescal.cli.progress.simulation_bar`), called only when runs are due.
    mcmc_progress
        Factory of an MCMC progress callback: ``(description, total) -> (tick, close)``.
    checkpoint_seconds
        Minimum wall time between two snapshots of an MCMC chain (a killed run
        resumes from the last one with identical draws). [s]
    """

    backend: str | None = None
    jobs: int | None = None
    scheduler: str | None = None
    chains_backend: str = "auto"
    progress: Callable[[int], tuple[Progress, Callable[[], None]]] | None = None
    mcmc_progress: Callable[[str, int], tuple[Tick, Callable[[], None]]] | None = None
    checkpoint_seconds: float = 30.0


@dataclass(frozen=True)
class Context:
    """A loaded study: configuration, measured data, simulator and output folder."""

    study: Study
    measured: MeasuredData
    simulator: Simulator
    out: Path
    options: Options

    @cached_property
    def priors(self) -> dict[str, Prior]:
        """The priors of the emulator's parameter inputs, in parameter order: the study's
        calibrated ones (``[study] prior_from`` applied: :mod:`bayescal.pipeline.sequential`)
        or, with ``[design] reuse_screening``, every parameter (:mod:`bayescal.pipeline.reuse`;
        :attr:`held` are not calibrated)."""
        from bayescal.pipeline.sequential import study_priors

        if self.study.design.reuse_screening:
            return emulator_priors(self.study)
        return study_priors(self.study)

    @property
    def held(self) -> dict[str, float]:
        """The emulator's inputs held at their nominal values in the calibration and the
        predictions (``[design] reuse_screening``'s screened-out candidates; else empty)."""
        return held_parameters(self.study)

    @property
    def transforms(self) -> dict[str, LogLevel]:
        """Calibrated outputs with relative errors -> their ``log(y + floor)`` map.

        The floor is the stated one, else 1 % of the mean measured value of the
        training periods (training data only).
        """
        out = {}
        outputs = self.study.outputs
        for name in outputs.calibrate:
            if outputs.relative(name):
                floor = outputs.floor(name)
                if floor is None:
                    train = self.measured.layout.cut(np.asarray(self.measured.outputs[name]))
                    floor = 0.01 * abs(float(np.nanmean(train)))
                out[name] = LogLevel(floor)
        return out

    def seed(self, stage: str, explicit: int | None = None) -> int:
        """The stage's seed: ``explicit`` or derived from the master seed."""
        return int(explicit) if explicit is not None else derived_seed(self.study.study.seed, stage)


def prepare(study: Study, options: Options | None = None) -> Context:
    """Load the measured data and build the simulator (errors surface here, before any run)."""
    measured = load_measured(study)
    # reused screening runs: the screening's simulator (every parameter free), whose
    # cache keys they have; new runs pass the nominal values of the screened-out ones
    simulator = study_simulator(study)
    out = study.root / study.study.output_dir
    ctx = Context(study, measured, simulator, out, options or Options())
    level_values(ctx, {n: measured.outputs[n] for n in ctx.transforms}, "measured")
    return ctx


def level_values(
    ctx: Context, series: Mapping[str, np.ndarray], what: str
) -> dict[str, np.ndarray]:
    """``series`` with the outputs of relative errors on their log scale (others as they are).

    Only the samples of the training periods and the test window are read (and
    must lie above ``-floor``); the others become NaN. Simulated series
    (``what = "simulated"``) are also read on the whole periods covering the test
    window (the first may begin before it): the emulator is conditioned on the
    design runs there (:func:`bayescal.pipeline.predict.emulator_with_test_window`).
    """
    transforms = ctx.transforms
    if not transforms:
        return dict(series)
    layout = ctx.measured.layout
    used = np.isin(windows(layout), ("train", "test"))
    if what == "simulated":
        for start in layout.test_starts:
            used[start : start + layout.period] = True
    return {
        name: transforms[name].forward(np.where(used, np.asarray(values, float), np.nan),
                                       f"{what} {name}")
        if name in transforms else values
        for name, values in series.items()
    }  # fmt: skip


def make_design(ctx: Context) -> Design:
    """The Latin hypercube of ``[design]`` over the priors' bounds; with ``reuse_screening``
    the screening's runs, then that hypercube over the calibrated parameters
    (:func:`bayescal.pipeline.reuse.reuse_design`; none with ``runs = 0``, which the
    configuration allows with ``sequential`` only: the sequential design's first design)."""
    section = ctx.study.design
    optimization = None if section.optimization == "none" else section.optimization
    seed = ctx.seed("design", section.seed)
    if not section.reuse_screening:
        return latin_hypercube(ctx.priors, section.runs, seed, optimization)
    calibrated = {name: ctx.priors[name] for name in ctx.study.calibrated}
    new = (
        latin_hypercube(calibrated, section.runs, seed, optimization)
        if section.runs
        else Design(calibrated, np.empty((0, len(calibrated))), seed=seed)
    )
    return reuse_design(ctx.study, new)


def _runner_options(ctx: Context) -> dict[str, Any]:
    runner, opt = ctx.study.runner, ctx.options
    backend = opt.backend or ("dask" if opt.scheduler else runner.backend)
    return {
        "backend": backend,
        "jobs": opt.jobs or runner.jobs,
        "scheduler": opt.scheduler or runner.scheduler,
        "timeout": runner.timeout,
        "retries": runner.retries,
    }


def simulate(ctx: Context, design: Design, need: int | None = None) -> RunResults:
    """Run the design (cached per run in ``out/simulations``); too many failures raise.

    ``need``: the fewest successful runs accepted (default: parameters + 2, what
    the emulator needs).

    Raises
    ------
    SimulatorError
        If fewer than ``t + 2`` runs succeeded (the emulator needs them).
    """
    factory = ctx.options.progress
    progress, close = factory(design.runs) if factory is not None else (None, lambda: None)
    try:
        results = run_design(
            ctx.simulator,
            ctx.measured.forcing,
            design,
            cache_dir=ctx.out / "simulations",
            progress=progress,
            **_runner_options(ctx),
        )
    finally:
        close()
    need = len(design.names) + 2 if need is None else need
    ok = design.runs - results.n_failed
    if ok < need:
        first = results.failures[0] if results.failures else None
        detail = f"; first error: {first.message}" if first else ""
        raise SimulatorError(
            f"only {ok} of {design.runs} simulator runs succeeded, at least {need} are needed"
            f"{detail}",
            hint=f"see {ctx.out / 'simulations' / 'failures'} for every failed run",
        )
    return results


def nominal_run(ctx: Context) -> dict[str, np.ndarray]:
    """The simulator at the nominal parameter values (through the run cache)."""
    nominal = nominal_parameters(ctx.study)
    design = Design.from_values(ctx.priors, [[nominal[n] for n in ctx.priors]])
    options = _runner_options(ctx) | {"backend": "serial"}
    options.pop("jobs")
    options.pop("scheduler")
    res = run_design(
        ctx.simulator,
        ctx.measured.forcing,
        design,
        cache_dir=ctx.out / "simulations",
        **options,
    )
    if res.failures:
        raise SimulatorError(f"the nominal run failed: {res.failures[0].message}")
    return {name: values[0] for name, values in res.outputs.items()}


@dataclass(frozen=True)
class EmulatorResult:
    """The assembled data, the trained emulator and its cross-validation."""

    assembled: Assembled
    emulator: Emulator
    loo: LooResult


def assemble_runs(ctx: Context, sims: RunResults) -> Assembled:
    """Cut, standardise and project the successful runs and the measurements."""
    design = Design(sims.design.priors, sims.unit, seed=sims.design.seed)
    section = ctx.study.emulator
    outputs = ctx.study.outputs
    noise = {
        name: NoiseSpec(spec.model, outputs.noise_sd(name), spec.discrepancy, spec.relative)
        for name in outputs.calibrate
        for spec in [outputs.errors.get(name, OutputError())]
    }
    return assemble(
        design,
        level_values(ctx, sims.outputs, "simulated"),
        level_values(ctx, ctx.measured.outputs, "measured"),
        ctx.measured.forcing.series,
        ctx.measured.layout,
        outputs=ctx.study.outputs.calibrate,
        variance=section.pca_variance,
        components=section.pca_components,
        input_variance=section.input_pca_variance,
        history=section.history_periods,
        scale=section.standardise,
        noise=noise,
    )


def _mcmc_tick(ctx: Context, what: str, total: int) -> tuple[Tick | None, Callable[[], None]]:
    factory = ctx.options.mcmc_progress
    if factory is None:
        return None, lambda: None
    return factory(what, total)


def build_emulator(
    ctx: Context,
    sims: RunResults,
    checkpoint_dir: Path | None = None,
    warm: EmulatorResult | None = None,
) -> EmulatorResult:
    """Assemble, train the emulator (MwG + MAP) and cross-validate it; ``warm`` (an
    emulator of the same inputs on fewer runs) starts the MAP search of each basis
    from its MAP (:func:`bayescal.emulator.train`)."""
    assembled = assemble_runs(ctx, sims)
    section = ctx.study.emulator
    n_chains = 2
    tick, close = _mcmc_tick(ctx, "emulator", n_chains * (section.burn + section.samples))
    try:
        emulator = train(
            assembled,
            method=section.training,
            n_burn=section.burn,
            n_draws=section.samples,
            n_chains=n_chains,
            seed=ctx.seed("emulator"),
            backend=ctx.options.chains_backend,  # type: ignore[arg-type]
            callback=tick,
            checkpoint_dir=checkpoint_dir,
            checkpoint_seconds=ctx.options.checkpoint_seconds,
            warm=None if warm is None else warm.emulator,
        )
    finally:
        close()
    return EmulatorResult(assembled, emulator, emulator.loo_cv())


def calibrate_stage(
    ctx: Context,
    em: EmulatorResult,
    priors: dict[str, Prior] | None = None,
    checkpoint_dir: Path | None = None,
    starts: np.ndarray | None = None,
) -> Posterior:
    """Sample theta*, lambda and lambda* (``[calibration]``); the chains start at
    ``starts`` (``(chains, t)`` on the normalised scale, NaN: the default start) or,
    with ``[study] prior_from``, from the previous posterior's draws
    (:func:`bayescal.pipeline.sequential.warm_starts`)."""
    from bayescal.pipeline import sequential  # looked up at call time (tests replace it)

    section = ctx.study.calibration
    total = section.chains * (section.burn + section.samples)
    tick, close = _mcmc_tick(ctx, "calibration", total)

    def extend(kept: int, longer: int) -> Tick | None:
        nonlocal close
        close()
        label = f"calibration, extended to {longer} draws"
        new_tick, close = _mcmc_tick(ctx, label, section.chains * (section.burn + longer))
        return new_tick

    try:
        post = calibrate(
            em.emulator,
            em.assembled,
            priors,
            n_chains=section.chains,
            n_burn=section.burn,
            n_draws=section.samples,
            seed=ctx.seed("calibrate", section.seed),
            backend=ctx.options.chains_backend,  # type: ignore[arg-type]
            algebra=ctx.study.emulator.algebra,
            sampler=section.sampler,
            callback=tick,
            checkpoint_dir=checkpoint_dir,
            checkpoint_seconds=ctx.options.checkpoint_seconds,
            observations=em.assembled.observations,
            moves=section.moves,
            max_draws=section.most_samples,
            on_extend=extend,
            starts=sequential.warm_starts(ctx.study, section.chains) if starts is None else starts,
            fixed=ctx.held,
        )
    finally:
        close()
    return post.with_derived(derived_draws(ctx, post))


def _derived_values(
    ctx: Context, names: tuple[str, ...], values: np.ndarray
) -> dict[str, tuple[np.ndarray, str, str]]:
    """The simulator's derived quantities and the study's ``[derived]`` at each row of
    ``values`` (``(rows, len(names))``, physical units): quantity -> (values, unit, text)."""
    out: dict[str, tuple[np.ndarray, str, str]] = {}
    sim = ctx.simulator
    if isinstance(sim, Derivable) and sim.derived_units:
        rows = [sim.derived(dict(zip(names, map(float, row), strict=True))) for row in values]
        for quantity, (unit, text) in sim.derived_units.items():
            out[quantity] = (np.array([r[quantity] for r in rows]), unit, text)
    by_name = {n: values[:, k] for k, n in enumerate(names)}
    for quantity, expression in ctx.study.expressions().items():
        spec = ctx.study.derived[quantity]
        column = np.broadcast_to(expression.evaluate(by_name), values.shape[:1])
        out[quantity] = (np.asarray(column, dtype=float), spec.unit, spec.description)
    return out


def derived_draws(ctx: Context, posterior: Posterior) -> dict[str, Derived]:
    """The simulator's derived quantities and the study's ``[derived]`` at every draw."""
    return derived_at(ctx, tuple(posterior.names), posterior.draws)


def derived_at(ctx: Context, names: tuple[str, ...], draws: np.ndarray) -> dict[str, Derived]:
    """:func:`derived_draws` at draws ``(chains, draws, len(names))`` of ``names``
    (physical units; the study's other parameters at their nominal values)."""
    found = _derived_values(ctx, names, draws.reshape(-1, len(names)))
    return {
        quantity: Derived(column.reshape(draws.shape[:2]), unit, text)
        for quantity, (column, unit, text) in found.items()
    }


def nominal_derived(ctx: Context, names: tuple[str, ...]) -> dict[str, float]:
    """The derived quantities at the nominal parameters (their catalogue values).

    ``names`` are the calibrated parameters, as the posterior's draws hold them
    (the others keep their nominal values in the simulator either way).
    """
    nominal = nominal_parameters(ctx.study)
    values = np.array([[nominal[n] for n in names]], dtype=float)
    return {q: float(v[0]) for q, (v, _, _) in _derived_values(ctx, names, values).items()}


def discrepancy_stage(
    ctx: Context,
    em: EmulatorResult,
    posterior: Posterior,
    checkpoint_dir: Path | None = None,
) -> Discrepancy | None:
    """The difference process (``[discrepancy] enabled``), else ``None``.

    The chains run in lockstep in this process (whatever the chains backend).
    The progress total is the length of the first convergence check; chains
    that are extended past it keep counting.
    """
    section = ctx.study.discrepancy
    if not section.enabled:
        return None
    from bayescal.discrepancy import estimate_discrepancy

    cal = ctx.study.calibration
    n_burn, n_draws, max_draws = ctx.study.discrepancy_lengths()
    tick, close = _mcmc_tick(ctx, "discrepancy", cal.chains * (n_burn + n_draws))
    try:
        return estimate_discrepancy(
            em.emulator,
            em.assembled,
            posterior,
            realisations=section.realisations,
            update_interval=section.update_interval,
            n_chains=cal.chains,
            n_burn=n_burn,
            n_draws=n_draws,
            max_draws=max_draws,
            seed=ctx.seed("discrepancy"),
            callback=tick,
            checkpoint_dir=checkpoint_dir,
            checkpoint_seconds=ctx.options.checkpoint_seconds,
        )
    finally:
        close()


@dataclass(frozen=True)
class Predictions:
    """Series on the study clock and the metrics table."""

    dataset: xr.Dataset
    metrics: pd.DataFrame


def predict_stage(
    ctx: Context,
    em: EmulatorResult,
    posterior: Posterior,
    discrepancy: Discrepancy | None = None,
    nominal: dict[str, np.ndarray] | None = None,
    method: str | None = None,
    off_basis: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
) -> Predictions:
    """Nominal, calibrated (and corrected) predictions with bands, and their metrics.

    ``method`` (``"emulator"`` or ``"simulator"``) overrides ``[predict] method``:
    the route that ``method = "auto"`` chose (:mod:`bayescal.pipeline.route`).
    ``off_basis`` (emulator route): the held-out runs' part off the output basis
    that completes the calibrated prediction's centre (:mod:`bayescal.pipeline.completed`;
    not the corrected one's: the difference process, estimated against the
    emulator's centre on the basis, already holds that part).
    """
    section = ctx.study.predict
    route = method or section.method
    if route == "auto":
        raise ValueError("predict_stage needs the route 'auto' chose (bayescal.pipeline.route)")
    band = _band(ctx, em, posterior, None, route, off_basis)
    corrected = delta = None
    if discrepancy is not None:
        # Delta was estimated against the emulator's centre on the basis, so it already
        # holds the part off the basis: the corrected prediction stays emulator + Delta
        corrected = _band(ctx, em, discrepancy.posterior, discrepancy, route)
        delta = delta_series(em.assembled, discrepancy, list(em.emulator.outputs.names))
    m = ctx.measured
    held = ctx.study.outputs.held_out
    ds = predictions_dataset(
        m.times,
        m.layout,
        {o: m.outputs[o] for o in ctx.study.outputs.calibrate} | dict(m.held_out),
        nominal if nominal is not None else nominal_run(ctx),
        band,
        m.forcing.series,
        corrected,
        delta,
        attrs={
            "level": section.level,
            "study": ctx.study.study.name,
            "held_out": ",".join(held),
            "route": route,
            "off_basis": "completed by the held-out runs" if off_basis else "",
        },
    )
    return Predictions(ds, metrics_table(ds))


def held_out_sd(ctx: Context, name: str) -> float:
    """A held-out sensor's noise SD: its stated accuracy (a range: the geometric mean)."""
    value = ctx.study.outputs.noise_sd(name)
    if value is None:  # pragma: no cover - the study's validation requires it
        raise ConfigError(f"outputs.held_out: {name!r} has no [outputs.errors.{name}] sd")
    return float(value) if isinstance(value, float) else float(np.sqrt(value[0] * value[1]))


def posterior_runs(
    ctx: Context, posterior: Posterior, n: int
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The simulator at ``n`` posterior draws (thinned evenly).

    Returns the outputs of the runs that succeeded, their lambda*s and their
    draws' indices in the posterior's flattened draws.
    """
    theta = posterior.draws.reshape(-1, len(posterior.names))
    lam_stars = posterior.lam_stars.reshape(theta.shape[0], -1)
    pick = np.unique(np.linspace(0, theta.shape[0] - 1, min(n, theta.shape[0])).astype(int))
    design = Design.from_values(ctx.priors, theta[pick])
    # as many successful runs as the calibrated parameters + 2 (reuse_screening's held
    # inputs are in the design but not in the count)
    res = simulate(ctx, design, need=len(ctx.study.calibrated) + 2)
    return res.outputs, lam_stars[pick][res.indices], pick[res.indices]


def _band(
    ctx: Context,
    em: EmulatorResult,
    posterior: Posterior,
    discrepancy: Discrepancy | None,
    route: str,
    off_basis: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
) -> Band:
    section = ctx.study.predict
    measured = {o: ctx.measured.outputs[o] for o in ctx.study.outputs.calibrate}
    # With method = "simulator" the model part is the simulator re-run at posterior
    # draws (of the Delta phase for the corrected prediction) and Delta is added to
    # it: Delta was estimated against the emulator on the training periods, where
    # the emulator reproduces the simulator (leave-one-run-out CV), but outside
    # their conditions only the simulator is trustworthy (Twin House test week:
    # emulator + Delta RMSE 2.25 W/m², simulator + Delta see docs/validation/case-studies-log.md).
    transforms = ctx.transforms
    if route == "simulator":
        runs, lam_star, drawn = posterior_runs(ctx, posterior, section.runs)
        model_runs = level_values(ctx, {o: runs[o] for o in em.emulator.outputs.names}, "simulated")
        if discrepancy is None:
            lam_star = simulator_noise(
                em.assembled, model_runs, posterior, drawn, section.noise, em.emulator
            )
        band = simulator_band(
            em.assembled,
            model_runs,
            lam_star,
            level=section.level,
            discrepancy=discrepancy,
            measured=measured,
            model_error=conditioned_discrepancy(
                em.emulator, em.assembled, posterior, drawn, model_runs, lam_stars=lam_star
            ),
            transforms=transforms,
        )
        held = ctx.study.outputs.held_out
        if discrepancy is not None or not held:
            return band
        extra = held_out_band(
            ctx.measured.layout,
            {o: runs[o] for o in held},
            {o: held_out_sd(ctx, o) for o in held},
            ctx.measured.held_out,
            section.level,
        )
        return merge_bands(band, extra)
    if off_basis:
        return completed_band(
            em.emulator,
            em.assembled,
            posterior,
            off_basis,
            draws=section.draws,
            level=section.level,
            noise=section.noise,
            discrepancy=discrepancy,
            measured=measured,
            transforms=transforms,
        )
    return predict_band(
        em.emulator,
        em.assembled,
        posterior,
        draws=section.draws,
        level=section.level,
        discrepancy=discrepancy,
        measured=measured,
        transforms=transforms,
    )
