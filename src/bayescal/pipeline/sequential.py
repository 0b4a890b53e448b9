"""A posterior as the next prior: ``[study] prior_from`` (``bayescal update`` chains it).

``[study] prior_from = "../other"`` reads the finished calibration of another
study and makes its posterior the prior of the parameters the two studies
share (same names): a :class:`~bayescal.design.LogitNormal` fitted to the
draws on *this* study's bounds (``z = logit((x - lower) / (upper - lower))``
Gaussian, mean and covariance of the draws' ``z``), so the correlation between
the shared parameters is kept; each keeps this study's bounds, which must hold
the previous posterior. The other parameters keep their own priors. How well
the density fits the draws is measured and stated
(:attr:`PriorFromDraws.fit`: the largest Kolmogorov-Smirnov distance between a
marginal of the draws and the density's marginal; a value above
:data:`FIT_WARN` is a warning: the posterior is skewed or multi-modal in a way
one Gaussian in logit space does not follow).

The calibration chains of such a study start from draws of the previous
posterior (:func:`warm_starts`), one draw per chain, spread from its centre to
its tails, instead of the dispersed default starts.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import special, stats

from bayescal.config import Study, load_study
from bayescal.design import PosteriorPrior, Prior, fit_logit_normal
from bayescal.errors import BayescalError, ConfigError
from bayescal.store import posterior as posterior_store
from bayescal.store.stages import StageLog

__all__ = [
    "FIT_WARN",
    "PriorFromDraws",
    "prior_from_draws",
    "spread_picks",
    "study_priors",
    "warm_starts",
]

#: Largest Kolmogorov-Smirnov distance of a marginal above which the fit is a warning.
FIT_WARN = 0.05


@dataclass(frozen=True)
class PriorFromDraws:
    """The priors of a study with ``prior_from``, and how they were made.

    Attributes
    ----------
    priors
        Every calibrated parameter's prior, in study order.
    shared
        The parameters whose prior is the previous posterior.
    source
        The other study's output folder.
    draws
        Draws the density was fitted to.
    fit
        Parameter -> KS distance between its draws' and the density's marginal.
    """

    priors: dict[str, Prior]
    shared: tuple[str, ...]
    source: Path
    draws: int
    fit: dict[str, float]

    def describe(self) -> str:
        """One line: where the prior comes from and how well it fits."""
        worst = max(self.fit, key=lambda n: self.fit[n])
        line = (
            f"prior of {', '.join(self.shared)} from the posterior of {self.source} "
            f"(logit-normal fitted to {self.draws} draws; largest KS distance of a marginal "
            f"{self.fit[worst]:.3f}, {worst})"
        )
        if self.fit[worst] > FIT_WARN:
            line += (
                f"; WARNING: above {FIT_WARN}: the previous posterior is not well described "
                "by one Gaussian in logit space"
            )
        return line


def _previous(study: Study) -> tuple[Any, Path, str] | None:
    """The finished posterior ``prior_from`` names, its output folder and the other
    study's file (``None`` without ``prior_from``).

    Raises
    ------
    ConfigError
        The other study cannot be read or has no finished calibration.
    """
    other_path = study.study.prior_from
    if other_path is None:
        return None
    try:
        other = load_study(other_path)
    except BayescalError as exc:
        raise ConfigError(
            f"study.prior_from: {exc.one_line()}", hint="give the folder of a calibrated study"
        ) from None
    out = other.root / other.study.output_dir
    file = out / posterior_store.FILE
    if not StageLog.open(out).finished("calibrate") or not file.is_file():
        raise ConfigError(
            f"study.prior_from: {out} holds no finished calibration",
            hint=f"run `bayescal run {other.path}` first",
        )
    try:
        return _posterior(str(file), file.stat().st_mtime_ns), out, str(other.path)
    except (BayescalError, OSError, ValueError, KeyError) as exc:
        raise ConfigError(f"study.prior_from: cannot read {file} ({exc})") from None


def warm_starts(study: Study, n_chains: int) -> np.ndarray | None:
    """Starts of the calibration chains from the previous posterior's draws.

    ``(n_chains, t)`` on the normalised scale of this study's bounds (the
    parameters' order), or ``None`` without ``prior_from``. Chain ``k`` starts
    at the draw whose Mahalanobis distance from the draws' mean (in logit
    space) is the ``(k + 0.5) / n_chains`` quantile of all distances: the
    chains start at different draws, from the centre of the previous
    posterior to its tails. Parameters the previous study does not calibrate
    are NaN (their default starts). A start on or beyond a bound is clipped
    inside it by :func:`bayescal.calibration.posterior.calibrate`.
    """
    found = _previous(study)
    if found is None:
        return None
    previous = found[0]
    own = study.priors()
    flat = previous.draws.reshape(-1, len(previous.names))
    starts = np.full((n_chains, len(own)), np.nan)
    shared = [(k, previous.names.index(n)) for k, n in enumerate(own) if n in previous.names]
    if not shared or flat.shape[0] == 0:
        return starts
    priors = list(own.values())
    unit = np.column_stack([priors[k].to_unit(flat[:, j]) for k, j in shared])
    picks = spread_picks(unit, n_chains)
    for column, (k, _) in enumerate(shared):
        starts[:, k] = unit[picks, column]
    return starts


def spread_picks(unit: np.ndarray, n: int) -> np.ndarray:
    """Indices of ``n`` rows of ``unit`` (draws ``(rows, k)`` in ``(0, 1)``) spread from
    the draws' centre to their tails: row ``k`` is the ``(k + 0.5) / n`` quantile of
    the Mahalanobis distances from the mean in logit space (columns that do not vary
    are left out of the distance)."""
    z = special.logit(np.clip(unit, 1e-9, 1 - 1e-9))
    centred = z - z.mean(axis=0)
    centred = centred[:, np.ptp(centred, axis=0) > 0.0]
    if centred.shape[1] == 0:
        return np.zeros(n, dtype=int)
    cov = np.atleast_2d(np.cov(centred, rowvar=False))
    distance = np.einsum("ij,ij->i", centred @ np.linalg.pinv(cov), centred)
    order = np.argsort(distance, kind="stable")
    return order[((np.arange(n) + 0.5) / n * len(order)).astype(int)]


def prior_from_draws(study: Study) -> PriorFromDraws | None:
    """The priors of ``study`` with its ``prior_from`` applied (``None`` without one).

    Raises
    ------
    ConfigError
        The other study cannot be read, has no finished calibration, shares no
        parameter, or its posterior reaches this study's bounds.
    """
    found = _previous(study)
    if found is None:
        return None
    previous, out, other_path = found
    own = study.priors()
    shared = tuple(n for n in own if n in previous.names)
    if not shared:
        raise ConfigError(
            f"study.prior_from: {other_path} calibrates {', '.join(previous.names)}, none of "
            f"this study's {', '.join(own)}",
            hint="a posterior carries over to parameters of the same name",
        )
    flat = previous.draws.reshape(-1, len(previous.names))
    columns = [previous.names.index(n) for n in shared]
    unit = np.column_stack(
        [own[n].to_unit(flat[:, j]) for n, j in zip(shared, columns, strict=True)]
    )
    try:
        joint = fit_logit_normal(shared, unit, str(out))
    except ConfigError as exc:
        raise ConfigError(f"study.prior_from: {exc.message}", hint=exc.hint) from None
    priors: dict[str, Prior] = {}
    for name, prior in own.items():
        if name in shared:
            priors[name] = PosteriorPrior(
                prior.lower,
                prior.upper,
                unit=prior.unit,
                description=prior.description,
                joint=joint,
                index=shared.index(name),
            )
        else:
            priors[name] = prior
    fit = {}
    z = special.logit(unit)
    for i, name in enumerate(shared):
        sd = float(np.sqrt(joint.cov[i][i]))
        fit[name] = float(stats.kstest(z[:, i], "norm", args=(joint.mean[i], sd)).statistic)
    return PriorFromDraws(priors, shared, out, int(flat.shape[0]), fit)


@functools.lru_cache(maxsize=4)
def _posterior(file: str, mtime_ns: int) -> Any:
    """A posterior file read once per version (``run`` and its stages ask for it)."""
    del mtime_ns  # part of the cache key only
    return posterior_store.load_posterior(Path(file))


def study_priors(study: Study) -> dict[str, Prior]:
    """The study's priors, with ``prior_from`` applied where it is set."""
    made = prior_from_draws(study)
    return study.priors() if made is None else made.priors
