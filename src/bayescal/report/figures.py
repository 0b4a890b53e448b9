"""Figures of the calibration report (matplotlib, Agg backend, PNG written atomically).

Every function takes arrays or result objects and a file path, writes one PNG
through :func:`bayescal.atomic.atomic_write` and returns the path, so each can be
used on its own. The figures follow the paper (``calibration-framework.md``):

* :func:`plot_posterior_histograms` -- theta* over its prior density (Figures 1-3, 6-9);
* :func:`plot_traces`, :func:`plot_pairs` -- MCMC traces per chain and a pair plot;
* :func:`plot_rho_sensitivity` -- the emulator's ``rho = exp(-beta / 4)`` per input and basis;
* :func:`plot_pca_variance` -- variance explained by the output PCA;
* :func:`plot_emulator_loo` -- leave-one-run-out predictions and standardised residuals;
* :func:`plot_fit` -- measured against predicted with a 95 % band (Figures 4, 10, 11);
* :func:`plot_delta_vs_boundary` -- the discrepancy against each boundary condition.

:func:`loo_predictions` recomputes the emulator's leave-one-run-out means and
standard deviations (``LooResult`` keeps only the standardised residuals).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")

import matplotlib.dates as mdates
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from bayescal.atomic import atomic_write
from bayescal.glossary import GLOSSARY

if TYPE_CHECKING:
    from bayescal.calibration.posterior import Posterior
    from bayescal.emulator.gp import Emulator

__all__ = [
    "label",
    "loo_predictions",
    "plot_delta_vs_boundary",
    "plot_emulator_loo",
    "plot_fit",
    "plot_pairs",
    "plot_pca_variance",
    "plot_posterior_histograms",
    "plot_rho_sensitivity",
    "plot_traces",
    "save_figure",
]

DPI = 100
MAX_POINTS = 20_000  # scatter points drawn per panel (evenly thinned beyond)
COLOURS = {"measured": "black", "nominal": "0.45", "model": "tab:red", "disc": "tab:blue"}
WINDOW_TITLES = {"train": "training window", "test": "test window", "new": "new conditions"}
FloatArray = NDArray[np.float64]


#: A posterior whose central 99 % spans less than this fraction of the prior gets a zoom.
ZOOM_FRACTION = 0.2


def label(name: str) -> str:
    """``name [unit]`` for glossary names, ``name`` otherwise."""
    q = GLOSSARY.get(name)
    return f"{name} [{q.unit}]" if q else name


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG atomically and close it."""
    try:
        target = atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=DPI))
    finally:
        plt.close(fig)
    return target


def _thin(n: int, limit: int = MAX_POINTS) -> NDArray[np.intp]:
    """At most ``limit`` indices spread evenly over ``range(n)``."""
    return np.unique(np.linspace(0, n - 1, min(n, limit)).astype(np.intp)) if n else np.arange(0)


def _grid(n: int, columns: int = 3) -> tuple[int, int]:
    cols = min(n, columns)
    return -(-n // cols), cols


# ----------------------------------------------------------------------------- posterior


def _prior_curve(ax: Axes, prior: object, lower: float, upper: float) -> None:
    logpdf = getattr(prior, "logpdf", None)
    if logpdf is None:
        return
    grid = np.linspace(lower, upper, 400)
    with np.errstate(divide="ignore"):
        density = np.exp(np.asarray(logpdf(grid), dtype=float))
    ax.plot(grid, density, color="0.3", lw=1.2, ls="--", label="prior")


def _columns(posterior: Posterior) -> dict[str, FloatArray]:
    flat = posterior.draws.reshape(-1, len(posterior.names))
    return {name: flat[:, k] for k, name in enumerate(posterior.names)}


def plot_posterior_histograms(
    path: str | Path, posterior: Posterior, discrepancy: Posterior | None = None
) -> Path:
    """Histogram of each theta* over its prior density, one panel per parameter.

    Parameters
    ----------
    path
        PNG file to write.
    posterior
        Calibration posterior (draws in physical units).
    discrepancy
        theta* of the discrepancy phase, overlaid as an outline when given.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    names, cols_kept = _calibrated(posterior)
    rows, cols = _grid(len(names))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    main = posterior.draws.reshape(-1, len(posterior.names))[:, cols_kept]
    extra = {} if discrepancy is None else _columns(discrepancy)
    for k, (ax, name) in enumerate(zip(axes.flat, names, strict=False)):
        prior = posterior.priors[name]
        lo, hi = float(prior.lower), float(prior.upper)
        bins = np.linspace(lo, hi, 41)
        ax.hist(main[:, k], bins=bins, density=True, color=COLOURS["model"], alpha=0.55)
        ax.plot([], [], color=COLOURS["model"], lw=6, alpha=0.55, label="posterior")
        if name in extra:
            ax.hist(
                extra[name],
                bins=bins,
                density=True,
                histtype="step",
                lw=1.5,
                color=COLOURS["disc"],
                label="posterior (with Δ)",
            )
        _prior_curve(ax, prior, lo, hi)
        _zoom(ax, main[:, k], hi - lo)
        ax.set_xlim(lo, hi)
        ax.set_xlabel(name)
        ax.set_ylabel("density")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    for ax in list(axes.flat)[len(names) :]:
        ax.set_visible(False)
    fig.suptitle("Posterior of θ* over its prior")
    fig.tight_layout()
    return save_figure(fig, path)


def _calibrated(posterior: Posterior) -> tuple[list[str], list[int]]:
    """theta*'s calibrated names and columns: the held ones (:attr:`Posterior.held_names`)
    left out, unless every one is held."""
    kept = [k for k, n in enumerate(posterior.names) if n not in posterior.held_names]
    kept = kept or list(range(len(posterior.names)))
    return [posterior.names[k] for k in kept], kept


def _zoom(ax: Axes, draws: FloatArray, prior_width: float) -> None:
    """An inset with the posterior on its own scale when it is narrow against the prior."""
    q_lo, q_hi = np.percentile(draws, [0.5, 99.5])
    if not q_hi - q_lo < ZOOM_FRACTION * prior_width:
        return
    pad = 0.15 * (q_hi - q_lo) if q_hi > q_lo else 1e-12
    inset = ax.inset_axes((0.04, 0.45, 0.4, 0.45))
    inset.hist(draws, bins=np.linspace(q_lo - pad, q_hi + pad, 31).tolist(), color=COLOURS["model"])
    inset.set_yticks([])
    inset.tick_params(labelsize=6)
    inset.set_title("zoom", fontsize=7)


def plot_traces(path: str | Path, posterior: Posterior) -> Path:
    """MCMC traces of theta*, lambda and lambda*, one line per chain.

    Parameters
    ----------
    path
        PNG file to write.
    posterior
        Calibration posterior.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    kept = [k for k, n in enumerate(posterior.all_names) if n not in posterior.held_names]
    draws = posterior.all_draws()[..., kept]
    names = [posterior.all_names[k] for k in kept]
    n_chains, n_draws, _ = draws.shape
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 1.7 * len(names)), sharex=True)
    axes = np.atleast_1d(axes)
    steps = np.arange(n_draws)
    for k, (ax, name) in enumerate(zip(axes, names, strict=True)):
        for c in range(n_chains):
            ax.plot(steps, draws[c, :, k], lw=0.6, alpha=0.8, label=f"chain {c + 1}")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncols=min(n_chains, 8), loc="upper right")
    axes[-1].set_xlabel("kept iteration")
    fig.suptitle("MCMC traces")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_pairs(path: str | Path, posterior: Posterior) -> Path:
    """Pair plot of theta*: histograms on the diagonal, scatter below it.

    Parameters
    ----------
    path
        PNG file to write.
    posterior
        Calibration posterior.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    names, cols_kept = _calibrated(posterior)
    t = len(names)
    flat = posterior.draws.reshape(-1, len(posterior.names))[:, cols_kept]
    pick = _thin(flat.shape[0], 4000)
    size = max(2.2 * t, 4.0)
    fig, axes = plt.subplots(t, t, figsize=(size, size), squeeze=False)
    for i in range(t):
        for j in range(t):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(flat[:, i], bins=30, color=COLOURS["model"], alpha=0.6)
                ax.set_yticks([])
            else:
                ax.scatter(
                    flat[pick, j],
                    flat[pick, i],
                    s=2,
                    alpha=0.3,
                    color=COLOURS["model"],
                    rasterized=True,
                )
            if i == t - 1:
                ax.set_xlabel(names[j])
            if j == 0 and i > 0:
                ax.set_ylabel(names[i])
            ax.tick_params(labelsize=7)
    fig.suptitle("Posterior pairs of θ*")
    fig.tight_layout()
    return save_figure(fig, path)


# ----------------------------------------------------------------------------- emulator


def plot_rho_sensitivity(path: str | Path, rho: ArrayLike, input_labels: Sequence[str]) -> Path:
    """Heatmap of the emulator's correlation parameters ``rho`` per basis and input.

    Small ``rho`` means the basis weight varies strongly with that input
    (an influential input); ``rho`` near 1 means no influence.

    Parameters
    ----------
    path
        PNG file to write.
    rho
        ``exp(-beta / 4)``, shape ``(p, r)``. [-]
    input_labels
        Labels of the ``r`` inputs ``[theta, x]``.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    values = np.atleast_2d(np.asarray(rho, dtype=float))
    p, r = values.shape
    if r != len(input_labels):
        raise ValueError(f"rho has {r} columns, got {len(input_labels)} input labels")
    fig, ax = plt.subplots(figsize=(max(5.0, 0.65 * r + 2.5), max(2.5, 0.5 * p + 1.8)))
    image = ax.imshow(values, vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto")
    ax.set_xticks(range(r), [str(s) for s in input_labels], rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(p), [f"basis {j + 1}" for j in range(p)], fontsize=8)
    if p * r <= 300:
        for j in range(p):
            for i in range(r):
                colour = "white" if values[j, i] < 0.6 else "black"
                ax.text(
                    i, j, f"{values[j, i]:.2f}", ha="center", va="center", fontsize=7, color=colour
                )
    fig.colorbar(image, ax=ax, label="ρ = exp(−β/4)")
    ax.set_title("Emulator sensitivity ρ per input and basis (small: influential)", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_pca_variance(path: str | Path, explained: ArrayLike, p: int) -> Path:
    """Variance explained by each principal component of the outputs, and cumulative.

    Parameters
    ----------
    path
        PNG file to write.
    explained
        Fraction of variance per component, non-increasing (``Basis.explained``). [-]
    p
        Number of components kept.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    frac = np.asarray(explained, dtype=float).ravel()
    shown = frac[: max(p, min(frac.size, max(10, 2 * p)))]
    idx = np.arange(1, shown.size + 1)
    fig, (ax, ax_r) = plt.subplots(1, 2, figsize=(11, 3.8))
    colours = [COLOURS["model"] if k < p else "0.7" for k in range(shown.size)]
    ax.bar(idx, 100.0 * shown, color=colours, label="per component")
    ax.plot(idx, 100.0 * np.cumsum(shown), "o-", color="black", ms=3, label="cumulative")
    ax.set_ylabel("variance explained [%]")
    ax.set_ylim(0.0, 102.0)
    ax.set_title(f"Output PCA: {100.0 * float(np.sum(frac[:p])):.2f} % kept", fontsize=10)
    remaining = np.clip(1.0 - np.cumsum(shown), 1e-16, None)
    ax_r.semilogy(idx, 100.0 * remaining, "o-", color="black", ms=3)
    ax_r.set_ylabel("variance left out [%]")
    ax_r.set_title("Variance outside the first k components", fontsize=10)
    for a in (ax, ax_r):
        a.axvline(p + 0.5, color="0.3", ls="--", lw=1, label=f"kept: p = {p}")
        a.set_xlabel("component k")
        a.set_xticks(idx)
        a.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="center right")
    fig.tight_layout()
    return save_figure(fig, path)


def loo_predictions(emulator: Emulator) -> dict[str, tuple[FloatArray, FloatArray, FloatArray]]:
    """Leave-one-run-out predictions of the emulator in the outputs' units.

    Each run is predicted from the others at the MAP hyperparameters, in closed
    form (:meth:`bayescal.emulator.gp.Emulator.loo_predict`, which
    :meth:`~bayescal.emulator.gp.Emulator.loo_cv` summarises).

    Parameters
    ----------
    emulator
        A trained emulator.

    Returns
    -------
    dict
        Output name -> ``(simulated, mean, sd)``, each ``(R, n_q, m*)`` in the
        output's unit: the held-out simulation, the predictive mean and the
        predictive standard deviation (including ``1 / lambda``).
    """
    n_runs, n_per = emulator.theta.shape[0], emulator.x.shape[0]
    scale = emulator.outputs.sd[None, :, None]
    centre = emulator.outputs.mean[None, :, None]
    m, v = emulator.loo_predict()
    sim = emulator.y_std.reshape(-1, n_runs, n_per).transpose(1, 0, 2) * scale + centre
    mean = m * scale + centre
    sd = np.sqrt(v) * scale
    return {
        name: (sim[:, sl], mean[:, sl], sd[:, sl]) for name, sl in emulator.outputs.slices.items()
    }


def plot_emulator_loo(
    path: str | Path,
    simulated: Mapping[str, ArrayLike],
    predicted: Mapping[str, ArrayLike],
    z: Mapping[str, ArrayLike],
    rmse: Mapping[str, float] | None = None,
    log_scale: Sequence[str] = (),
) -> Path:
    """Leave-one-out check: predicted against simulated, and residuals against N(0, 1).

    Parameters
    ----------
    path
        PNG file to write.
    simulated, predicted
        Output name -> held-out simulations and their LOO means (any shape,
        same per output), in the output's unit.
    z
        Output name -> standardised residuals ``(y - mean) / sd``. [-]
    rmse
        Output name -> LOO RMSE shown in the title, in the output's unit.
    log_scale
        Outputs with relative errors: their values are ``log(y + floor)``.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    names = list(simulated)
    fig, axes = plt.subplots(len(names), 2, figsize=(10, 4.0 * len(names)), squeeze=False)
    for (ax_s, ax_z), name in zip(axes, names, strict=True):
        y = np.asarray(simulated[name], dtype=float).ravel()
        f = np.asarray(predicted[name], dtype=float).ravel()
        pick = _thin(y.size)
        ax_s.scatter(y[pick], f[pick], s=3, alpha=0.35, color=COLOURS["model"], rasterized=True)
        ends = [float(np.nanmin([y.min(), f.min()])), float(np.nanmax([y.max(), f.max()]))]
        ax_s.plot(ends, ends, color="black", lw=1, label="1:1")
        what = f"log({name} + floor)" if name in log_scale else label(name)
        ax_s.set_xlabel(f"simulated {what}")
        ax_s.set_ylabel(f"LOO predicted {what}")
        extra = f", RMSE {rmse[name]:.3g}" if rmse and name in rmse else ""
        ax_s.set_title(f"{name}: leave-one-run-out{extra}", fontsize=10)
        ax_s.grid(alpha=0.3)
        ax_s.legend(fontsize=8)
        zz = np.asarray(z[name], dtype=float).ravel()
        zz = zz[np.isfinite(zz)]
        ax_z.hist(
            np.clip(zz, -6.0, 6.0),
            bins=60,
            range=(-6.0, 6.0),
            density=True,
            color=COLOURS["model"],
            alpha=0.55,
            label="standardised residuals",
        )
        grid = np.linspace(-6.0, 6.0, 300)
        ax_z.plot(grid, stats.norm.pdf(grid), color="black", lw=1.2, label="N(0, 1)")
        inside = float(np.mean(np.abs(zz) <= 1.959964)) if zz.size else float("nan")
        ax_z.set_title(f"{name}: {100.0 * inside:.1f} % within ±1.96", fontsize=10)
        ax_z.set_xlabel("(simulated − mean) / sd  [-]")
        ax_z.set_ylabel("density")
        ax_z.grid(alpha=0.3)
        ax_z.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


# ----------------------------------------------------------------------------- predictions


def _window_panel(
    ax: Axes,
    times: NDArray[np.datetime64],
    mask: NDArray[np.bool_],
    series: Mapping[str, FloatArray | None],
    model_label: str,
) -> None:
    t = times[mask]
    lower, upper = series["lower"], series["upper"]
    if lower is not None and upper is not None:
        ax.fill_between(
            t, lower[mask], upper[mask], color=COLOURS["model"], alpha=0.2, lw=0, label="95 % band"
        )
    lower50, upper50 = series.get("lower50"), series.get("upper50")
    if lower50 is not None and upper50 is not None:
        ax.fill_between(
            t, lower50[mask], upper50[mask], color=COLOURS["model"], alpha=0.35, lw=0,
            label="50 % band",
        )  # fmt: skip
    measured, nominal = series["measured"], series["nominal"]
    if measured is not None:
        ax.plot(t, measured[mask], color=COLOURS["measured"], lw=0.8, label="measured")
    if nominal is not None:
        ax.plot(t, nominal[mask], color=COLOURS["nominal"], lw=0.8, ls="--", label="nominal")
    mean = series["mean"]
    if mean is not None:
        ax.plot(t, mean[mask], color=COLOURS["model"], lw=0.9, label=model_label)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncols=5, loc="upper right")


def _opt(values: ArrayLike | None) -> FloatArray | None:
    return None if values is None else np.asarray(values, dtype=float)


def plot_fit(
    path: str | Path,
    times: ArrayLike,
    window: ArrayLike,
    name: str,
    measured: ArrayLike,
    mean: ArrayLike,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    *,
    nominal: ArrayLike | None = None,
    model_label: str = "calibrated",
    windows: Sequence[str] = ("train", "test"),
    band50: tuple[ArrayLike | None, ArrayLike | None] = (None, None),
) -> Path:
    """Measured against predicted output on the training and test windows, with a band.

    One panel per window that holds a finite prediction (a figure with a note
    when none does).

    Parameters
    ----------
    path
        PNG file to write.
    times
        Sample instants (``datetime64``), ``(n_total,)``.
    window
        Window label of each sample (``"train"``, ``"test"``, ...), ``(n_total,)``.
    name
        Output name (glossary), for the axis label.
    measured, mean
        Measured series and prediction, ``(n_total,)``, in the output's unit.
    lower, upper
        Band limits, ``(n_total,)``, same unit.
    nominal
        The simulator at nominal parameters, drawn dashed when given.
    model_label
        Legend entry of the prediction.
    windows
        Windows to draw, in order.
    band50
        Limits of the 50 % band (drawn darker inside the outer one), when given.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    t = np.asarray(times).astype("datetime64[ns]")
    labels = np.asarray(window).astype(str)
    series = {
        "measured": _opt(measured),
        "mean": _opt(mean),
        "lower": _opt(lower),
        "upper": _opt(upper),
        "nominal": _opt(nominal),
        "lower50": _opt(band50[0]),
        "upper50": _opt(band50[1]),
    }
    pred = series["mean"]
    if pred is None or pred.shape != t.shape or labels.shape != t.shape:
        raise ValueError(f"times, window and mean must have the same length {t.shape}")
    present = [w for w in windows if np.any((labels == w) & np.isfinite(pred))]
    n_panels = max(len(present), 1)
    fig, axes = plt.subplots(n_panels, 1, figsize=(11, 3.3 * n_panels), squeeze=False)
    for ax, w in zip(axes[:, 0], present, strict=False):
        _window_panel(ax, t, labels == w, series, model_label)
        ax.set_title(f"{name}: {WINDOW_TITLES.get(w, w)}", fontsize=10)
        ax.set_ylabel(label(name))
        locator = mdates.AutoDateLocator()
        ax.xaxis.set_major_locator(locator)
        ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    if not present:
        axes[0, 0].text(0.5, 0.5, "no prediction in these windows", ha="center", va="center")
    axes[-1, 0].set_xlabel("time (UTC)")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_delta_vs_boundary(
    path: str | Path,
    name: str,
    delta: ArrayLike,
    boundary: Mapping[str, ArrayLike],
    correlation: Mapping[str, float] | None = None,
) -> Path:
    """Scatter of the discrepancy Delta against each boundary condition.

    Parameters
    ----------
    path
        PNG file to write.
    name
        Output name (glossary) of Delta.
    delta
        Delta of that output, ``(n,)``, in the output's unit.
    boundary
        Boundary condition name -> series ``(n,)`` at the same samples.
    correlation
        Boundary condition name -> Pearson r shown in the panel title; computed
        over the finite pairs when not given.

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    d = np.asarray(delta, dtype=float)
    names = list(boundary)
    rows, cols = _grid(max(len(names), 1))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.5 * rows), squeeze=False)
    for ax, b in zip(axes.flat, names, strict=False):
        v = np.asarray(boundary[b], dtype=float)
        ok = np.isfinite(d) & np.isfinite(v)
        pick = np.flatnonzero(ok)[_thin(int(ok.sum()))]
        ax.scatter(v[pick], d[pick], s=3, alpha=0.35, color=COLOURS["disc"], rasterized=True)
        r = correlation.get(b) if correlation else None
        if r is None:
            r = _pearson(v[ok], d[ok])
        ax.set_title(f"r = {r:.2f}", fontsize=10)
        ax.set_xlabel(label(b))
        ax.set_ylabel(f"Δ {label(name)}")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names) :]:
        ax.set_visible(False)
    fig.suptitle(f"Discrepancy of {name} against the boundary conditions")
    fig.tight_layout()
    return save_figure(fig, path)


def _pearson(a: FloatArray, b: FloatArray) -> float:
    if a.size < 3 or np.std(a) == 0.0 or np.std(b) == 0.0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])
