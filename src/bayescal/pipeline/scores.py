"""Leave-one-period-out scores of one calibration, kept in its study's output folder.

:func:`score_calibration` is the scoring step of ``bayescal compare``
(:mod:`bayescal.pipeline.compare`) for a calibrated variant and for the
catalogue model of :mod:`bayescal.pipeline.catalogue` alike: PSIS over the
training periods (:func:`bayescal.calibration.cv.leave_period_out`), exact
refits for the periods whose Pareto ``k`` exceeds 0.7, worst first, at most
``max_refits``, and the log-Jacobian of outputs with relative errors
(:func:`relative_jacobian`), so that every value is a density of the
measurements in their own units. The scores are saved with their key
(:mod:`bayescal.store.crossval`) and reused by a later comparison.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from bayescal.calibration.cv import PeriodScores, leave_period_out, refit_period, scored_outputs
from bayescal.calibration.posterior import Posterior
from bayescal.errors import ConfigError
from bayescal.mcmc.diagnostics import Diagnostics
from bayescal.pipeline.keys import digest, stage_keys
from bayescal.pipeline.stages import Context, EmulatorResult, Options
from bayescal.store import crossval as crossval_store

__all__ = ["Say", "progress_bar", "relative_jacobian", "score_calibration", "scores_key"]

Say = Callable[[str], None]


def progress_bar(
    options: Options, label: str, total: int
) -> tuple[Callable[[int], None] | None, Callable[[], Any]]:
    """A progress bar of ``options`` (``None`` and a no-op closer without one)."""
    factory = options.mcmc_progress
    if factory is None:
        return None, lambda: None
    return factory(label, total)


def scores_key(ctx: Context, em: EmulatorResult, draws_per_chain: int, *what: str) -> str:
    """The key the scores of ``ctx``'s calibration are saved with (``what``: another
    model of the same study, such as the catalogue's)."""
    # scores of a discrepancy over the conditions became kriged: a new key
    kriged = ("discrepancy kriged",) if em.assembled.observations.delta_over_conditions else ()
    calibrate = stage_keys(ctx)["calibrate"]
    return digest("leave-period-out", calibrate, draws_per_chain, *kriged, *what)


def score_calibration(
    label: str,
    ctx: Context,
    em: EmulatorResult,
    posterior: Posterior | Callable[[], Posterior],
    options: Options,
    max_refits: int,
    draws_per_chain: int,
    say: Say,
    *,
    file: str = crossval_store.FILE,
    what: tuple[str, ...] = (),
    held: np.ndarray | None = None,
    outputs: tuple[str, ...] | None = None,
) -> PeriodScores:
    """The leave-one-period-out scores of a calibration of ``ctx`` (physical units).

    Parameters
    ----------
    label
        The name in progress notes.
    ctx, em
        The study and its emulator stage.
    posterior
        The calibration's posterior, or what computes it (called only where the
        scores are not in ``file`` for their key).
    options
        Progress bars; the refits' chains run on ``ctx.options.chains_backend``.
    max_refits
        Exact refits at most (those already saved count).
    draws_per_chain
        Posterior draws per chain the scores use.
    say
        One-line notes.
    file
        The file in the study's output folder that keeps the scores (those of a
        subset of the outputs beside it, ``STEM.on-HASH.npz``).
    what
        Added to the key (another model of the same study).
    held
        theta* on the normalised scale held fixed in the refits, as in the
        posterior (the catalogue model; NaN: that coordinate sampled); ``None``:
        sampled, but for ``[design] reuse_screening``'s screened-out inputs (held at
        their nominal values, as in the calibration).
    outputs
        The calibrated outputs scored (``None``: all; a subset is what variants that
        calibrate different outputs share, :func:`~bayescal.calibration.cv.leave_period_out`).
    """
    obs = em.assembled.observations
    algebra = ctx.study.emulator.algebra
    try:
        picked = scored_outputs(obs, outputs)
    except ValueError as exc:
        raise ConfigError(f"{label}: {exc}") from None
    names = None if picked is None else tuple(obs.outputs[q].name for q in picked)
    on = () if names is None else ("scored on", *names)
    key = scores_key(ctx, em, draws_per_chain, *what, *on)
    path = ctx.out / file
    if names is not None:  # beside the scores of every output, not over them
        path = path.with_name(f"{path.stem}.on-{digest(*names)[:10]}{path.suffix}")
    scores = crossval_store.load_scores(path, key)
    if scores is None:
        post = posterior() if callable(posterior) else posterior
        tick, close = progress_bar(options, f"{label}: leave-period-out", obs.y_star.shape[1])
        try:
            scores = leave_period_out(
                em.emulator,
                obs,
                post,
                algebra=algebra,
                draws_per_chain=draws_per_chain,
                callback=tick,
                outputs=names,
            )
        finally:
            close()
        crossval_store.save_scores(scores, path, key)
    else:
        say(f"{label}: leave-period-out scores up to date, reused ({path.name})")
    todo = scores.refit_order()[: max(0, max_refits - int(np.sum(scores.refitted)))]
    cal = ctx.study.calibration
    priors = posterior.priors if isinstance(posterior, Posterior) else em.assembled.priors
    if held is None and ctx.held:  # reuse_screening's screened-out inputs, as in the posterior
        held = np.array(
            [float(p.to_unit(ctx.held[n])) if n in ctx.held else np.nan for n, p in priors.items()]
        )
    seed_name = "-".join((*what, "leave-period-out"))  # the same refit chains whatever is scored
    for i in todo:
        total = cal.chains * (cal.burn + cal.samples)
        tick, close = progress_bar(options, f"{label}: refit without period {i}", total)
        try:
            value, refit, pit = refit_period(
                em.emulator,
                obs,
                dict(priors),
                i,
                n_chains=cal.chains,
                n_burn=cal.burn,
                n_draws=cal.samples,
                seed=ctx.seed(f"{seed_name}-{i}"),
                backend=ctx.options.chains_backend,  # type: ignore[arg-type]
                algebra=algebra,
                draws_per_chain=draws_per_chain,
                callback=tick,
                moves=cal.moves,
                held=held,
                outputs=names,
            )
        finally:
            close()
        scores = scores.with_refits({i: value}, _refit_note(i, refit.diagnostics), {i: pit})
        crossval_store.save_scores(scores, path, key)
    return scores.shifted(relative_jacobian(ctx, names))


def relative_jacobian(ctx: Context, outputs: tuple[str, ...] | None = None) -> np.ndarray:
    """Per training period ``(m*,)``: the log-Jacobian of the outputs with relative errors
    (among ``outputs``; ``None``: every calibrated output).

    Their scores are densities of ``log(y + floor)``; adding ``-sum log(y + floor)``
    over a period's samples makes them densities of the measurements in their own
    units, comparable with a variant's absolute errors (zero without relative errors).
    """
    layout = ctx.measured.layout
    out = np.zeros(layout.m_star)
    for name, level in ctx.transforms.items():
        if outputs is not None and name not in outputs:
            continue
        train = layout.cut(np.asarray(ctx.measured.outputs[name], dtype=float))
        out += level.log_jacobian(train).sum(axis=0)
    return out


def _refit_note(period: int, diag: Diagnostics) -> list[str]:
    """One line for a refit whose chains raised diagnostic warnings, else none."""
    if diag.ok:
        return []
    return [
        f"the refit without period {period} has {len(diag.warnings)} diagnostic warning(s) "
        f"(largest R-hat {np.nanmax(diag.rhat):.3f}, smallest bulk ESS "
        f"{np.nanmin(diag.ess_bulk):.0f}); longer [calibration] chains make its value firmer"
    ]
