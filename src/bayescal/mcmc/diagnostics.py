"""Convergence diagnostics of several chains, computed with ArviZ.

R-hat is ArviZ's rank-normalised split R-hat (the larger of the bulk and the
folded version; Vehtari, Gelman, Simpson, Carpenter & Bürkner 2021,
"Rank-normalization, folding, and localization: an improved R-hat"), ESS the
bulk and tail effective sample sizes of the same paper, MCSE the Monte Carlo
standard errors of the mean and of the standard deviation.

Nothing passes silently: :func:`diagnose` returns every problem as a warning
string naming the parameter and the value,

* R-hat above ``rhat_max`` (1.01) or not computable;
* bulk or tail ESS below ``ess_min`` (400, i.e. 100 per chain for 4 chains);
* a chain whose acceptance rate for a parameter is below ``min_acceptance``
  or that never moved a parameter (zero variance): a stuck chain;
* fewer than ``min_chains`` (4) chains.

Fixed parameters (acceptance ``NaN`` in every chain) are reported but not judged.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.errors import ConfigError
from bayescal.mcmc.chains import Chains

#: The thresholds :func:`diagnose` judges by default (Vehtari et al. 2021).
RHAT_MAX = 1.01
ESS_MIN = 400.0


def extended_length(kept: int, most: int, growth: float = 1.5) -> int:
    """The next length of chains that failed their diagnostics after ``kept`` draws:
    ``growth`` times as long (at least one draw more), at most ``most``.

    Shared by the calibration (:func:`bayescal.calibration.posterior.calibrate`) and
    the difference-process phase, which both run until they converge.
    """
    return min(most, max(kept + 1, math.ceil(kept * growth)))


if TYPE_CHECKING:
    import pandas as pd
    from arviz import InferenceData


def import_arviz() -> ModuleType:
    """Import ArviZ without its once-a-day notice about the coming 1.0 refactor.

    ArviZ 0.2x emits a ``FutureWarning`` on import that concerns its own API
    migration, not anything bayescal calls; with warnings as errors it would
    break the first import of the day.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message=r"\s*ArviZ is undergoing a major refactor", category=FutureWarning
        )
        import arviz

    return arviz


@dataclass(frozen=True)
class Diagnostics:
    """Per-parameter diagnostics and the list of problems found.

    Attributes
    ----------
    names
        Parameter names, ``(d,)``.
    mean, sd
        Posterior mean and standard deviation over all chains, ``(d,)``.
    rhat
        Rank-normalised split R-hat, ``(d,)`` (NaN where not computable).
    ess_bulk, ess_tail
        Bulk and tail effective sample sizes, ``(d,)``.
    mcse_mean, mcse_sd
        Monte Carlo standard errors of the mean and of the sd, ``(d,)``.
    acceptance
        Acceptance rate per chain and parameter, ``(n_chains, d)``, if known.
    warnings
        One explicit sentence per problem; empty when all checks pass.
    """

    names: tuple[str, ...]
    mean: NDArray[np.float64]
    sd: NDArray[np.float64]
    rhat: NDArray[np.float64]
    ess_bulk: NDArray[np.float64]
    ess_tail: NDArray[np.float64]
    mcse_mean: NDArray[np.float64]
    mcse_sd: NDArray[np.float64]
    acceptance: NDArray[np.float64] | None
    warnings: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """True when no check raised a warning."""
        return not self.warnings

    def table(self) -> pd.DataFrame:
        """The per-parameter values as a DataFrame indexed by parameter name.

        ``acceptance`` is the mean over chains.
        """
        import pandas as pd

        columns = {
            "mean": self.mean,
            "sd": self.sd,
            "mcse_mean": self.mcse_mean,
            "mcse_sd": self.mcse_sd,
            "ess_bulk": self.ess_bulk,
            "ess_tail": self.ess_tail,
            "r_hat": self.rhat,
        }
        if self.acceptance is not None:
            columns["acceptance"] = self.acceptance.mean(axis=0)  # NaN for fixed ones
        return pd.DataFrame(columns, index=pd.Index(self.names, name="parameter"))


def _as_array(
    source: Chains | ArrayLike, names: Sequence[str] | None, acceptance: ArrayLike | None
) -> tuple[NDArray[np.float64], tuple[str, ...], NDArray[np.float64] | None]:
    acc: NDArray[np.float64] | None
    if isinstance(source, Chains):
        draws = source.draws
        names = source.names if names is None else names
        acc = source.acceptance if acceptance is None else np.asarray(acceptance, dtype=float)
    else:
        draws = np.asarray(source, dtype=float)
        acc = None if acceptance is None else np.asarray(acceptance, dtype=float)
    if draws.ndim != 3 or draws.shape[1] < 4:
        raise ConfigError(f"draws must have shape (n_chains, n_draws >= 4, d), got {draws.shape}")
    d = draws.shape[2]
    out_names = tuple(names) if names is not None else tuple(f"x{i}" for i in range(d))
    if len(out_names) != d or len(set(out_names)) != d:
        raise ConfigError(f"need {d} distinct parameter names, got {list(out_names)}")
    if acc is not None and acc.shape != (draws.shape[0], d):
        raise ConfigError(f"acceptance must have shape {(draws.shape[0], d)}, got {acc.shape}")
    return draws, out_names, acc


def to_inference_data(
    source: Chains | ArrayLike, names: Sequence[str] | None = None
) -> InferenceData:
    """ArviZ ``InferenceData`` with a ``posterior`` group (chain, draw) per parameter.

    Parameters
    ----------
    source
        :class:`~bayescal.mcmc.chains.Chains`, or draws
        ``(n_chains, n_draws, d)``.
    names
        Parameter names (default: the chains' names, or ``x0, x1, ...``).

    Returns
    -------
    arviz.InferenceData
        ``posterior`` with one variable per parameter; for ``Chains`` also
        ``sample_stats.lp`` (the log-density) and the root seed in the attributes.
    """
    draws, names_t, _ = _as_array(source, names, None)
    az = import_arviz()
    posterior = {name: draws[:, :, k] for k, name in enumerate(names_t)}
    if isinstance(source, Chains):
        return az.from_dict(
            posterior=posterior,
            sample_stats={"lp": source.log_density},
            attrs={"seed": source.seed},
        )
    return az.from_dict(posterior=posterior)


#: The statistics of :func:`diagnose`: key -> (ArviZ function, its ``method``).
STATISTICS = {
    "rhat": ("rhat", "rank"),
    "ess_bulk": ("ess", "bulk"),
    "ess_tail": ("ess", "tail"),
    "mcse_mean": ("mcse", "mean"),
    "mcse_sd": ("mcse", "sd"),
}


def _arviz_values(
    draws: NDArray[np.float64], names: tuple[str, ...]
) -> dict[str, NDArray[np.float64]]:
    """R-hat, ESS and MCSE per parameter (NaN for parameters that never move)."""
    az = import_arviz()
    idata = to_inference_data(draws, names)
    # Degenerate parameters divide 0 by 0 inside ArviZ; they are detected below
    # and reported as warnings, so numpy's floating-point warnings are muted here.
    values = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        for key, (function, method) in STATISTICS.items():
            result = getattr(az, function)(idata, method=method)  # every parameter at once
            values[key] = np.array([float(result[n]) for n in names])
    half = draws.shape[1] // 2
    halves = np.concatenate([draws[:, :half], draws[:, half : 2 * half]], axis=0)
    frozen = np.all(np.ptp(halves, axis=1) == 0, axis=0)
    for v in values.values():
        v[frozen] = np.nan
    return values


def diagnose(
    source: Chains | ArrayLike,
    names: Sequence[str] | None = None,
    acceptance: ArrayLike | None = None,
    *,
    rhat_max: float = RHAT_MAX,
    ess_min: float = ESS_MIN,
    min_acceptance: float = 0.01,
    min_chains: int = 4,
) -> Diagnostics:
    """Diagnose chains and list every problem found.

    Parameters
    ----------
    source
        :class:`~bayescal.mcmc.chains.Chains`, or draws
        ``(n_chains, n_draws, d)``.
    names
        Parameter names (default: the chains' names, or ``x0, x1, ...``).
    acceptance
        Acceptance rates ``(n_chains, d)`` (default: the chains' own; ``NaN``
        marks a fixed parameter).
    rhat_max
        Largest acceptable R-hat.
    ess_min
        Smallest acceptable bulk and tail ESS.
    min_acceptance
        Acceptance rate below which a chain counts as stuck.
    min_chains
        Fewest chains for a trustworthy R-hat.

    Returns
    -------
    Diagnostics
    """
    draws, names_t, acc = _as_array(source, names, acceptance)
    values = _arviz_values(draws, names_t)
    fixed = np.zeros(len(names_t), dtype=bool) if acc is None else np.all(np.isnan(acc), axis=0)
    found: list[str] = []
    if draws.shape[0] < min_chains:
        found.append(
            f"only {draws.shape[0]} chain(s): R-hat needs at least {min_chains} "
            "chains from dispersed starting points to detect non-convergence"
        )
    for k, name in enumerate(names_t):
        if not fixed[k]:
            found.extend(
                _stuck(draws[:, :, k], None if acc is None else acc[:, k], name, min_acceptance)
            )
            found.extend(
                _thresholds({key: v[k] for key, v in values.items()}, name, rhat_max, ess_min)
            )
    pooled = draws.reshape(-1, draws.shape[2])
    return Diagnostics(
        names=names_t,
        mean=pooled.mean(axis=0),
        sd=pooled.std(axis=0, ddof=1),
        acceptance=acc,
        warnings=tuple(found),
        **values,
    )


def _stuck(
    draws: NDArray[np.float64], acc: NDArray[np.float64] | None, name: str, min_acceptance: float
) -> list[str]:
    """Warnings for chains that never move ``name`` or rarely accept."""
    found = []
    for c in range(draws.shape[0]):
        if np.ptp(draws[c]) == 0:
            found.append(
                f"chain {c} is stuck: {name!r} never moved "
                f"(all {draws.shape[1]} draws equal {draws[c, 0]:.6g})"
            )
        elif acc is not None and acc[c] < min_acceptance:
            found.append(
                f"chain {c} is stuck: acceptance rate of {name!r} is {acc[c]:.4f} "
                f"< {min_acceptance}; check the proposal scale and the starting point"
            )
    return found


def _thresholds(v: dict[str, float], name: str, rhat_max: float, ess_min: float) -> list[str]:
    """Warnings for R-hat and ESS of one parameter."""
    if np.isnan(v["rhat"]):
        return [f"R-hat of {name!r} cannot be computed: no chain moves it"]
    found = []
    if v["rhat"] > rhat_max:
        found.append(
            f"R-hat of {name!r} is {v['rhat']:.4f} > {rhat_max}: the chains disagree; "
            "run longer, or look for several modes or a stuck chain"
        )
    for kind in ("bulk", "tail"):
        ess = v[f"ess_{kind}"]
        if not ess >= ess_min:
            found.append(
                f"{kind} ESS of {name!r} is {ess:.0f} < {ess_min:.0f}: too few effective "
                "draws for reliable estimates; run the chains longer"
            )
    return found
