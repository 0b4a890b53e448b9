"""The report's account of uncertainty: noise, what the data fix, and whether bands hold.

One section (:func:`uncertainty_section`) and its figures
(:func:`uncertainty_figures`): the measurement noise of each output in its unit;
the principal directions of the posterior relative to the prior, the
prior-to-posterior contraction and the posterior correlation matrix
(:mod:`bayescal.calibration.identifiability`); what a prediction band
includes, its Monte Carlo error; and PIT histograms of the measured samples
under the predictive distribution (flat when the bands mean what they say).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from html import escape
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from bayescal.calibration.identifiability import Identifiability, identifiability
from bayescal.calibration.posterior import Posterior
from bayescal.report.answer import DISCREPANCY_KINDS
from bayescal.report.figures import save_figure

__all__ = ["BAND_TEXT", "plot_correlation", "plot_pit", "uncertainty_section"]

NOISE_TEXT = (
    "The noise SD is learnt from what the output basis leaves of the measurements: the "
    "sensor's noise and the part of the measured signal that no model run represents in "
    "that basis (on the exact virtual wall of the tests about 10 % above the injected noise). "
    "Read it as an upper estimate of the sensor's noise."
)
BAND_TEXT = (
    "A band is the central interval of the predictive distribution of a measurement: "
    "the model's prediction at each posterior draw of θ* (parameter uncertainty), the "
    "emulator's own interpolation uncertainty (emulator predictions: conditioned also on "
    "the design runs over the test window, and on the test window the part of the "
    "runs outside the output basis beyond the training periods' share; where the held-out "
    "runs of method = 'auto' complete its centre off the basis, that part's mean and its "
    "spread over those runs instead), the measurement noise of that draw (its error model; "
    "when the simulator is re-run for the bands, or the emulator's centre is completed, "
    "estimated again from the residuals on the training periods, because the noise SD "
    "below also holds the emulator's own error), an output's in-likelihood discrepancy "
    "conditioned on the training residuals, and, for the corrected prediction, the "
    "difference process Δ. Its edges are quantiles of that mixture computed exactly, not "
    "percentiles of a few random realisations; the Monte Carlo error below comes from the "
    "finite number of posterior draws. The test window was used for nothing but these "
    "final metrics: parameters, priors and error models are chosen on the training "
    "periods (bayescal compare)."
)


def plot_pit(path: Path, ds: xr.Dataset, outputs: Sequence[str]) -> Path:
    """Histograms of the PIT values per output and window (flat when calibrated)."""
    keys = [(o, w) for o in outputs for w in ("train", "test") if f"{o}_calibrated_pit" in ds]
    fig, axes = plt.subplots(1, max(len(keys), 1), figsize=(3.4 * max(len(keys), 1), 2.8))
    axes = np.atleast_1d(axes)
    window = ds["window"].values
    for ax, (o, w) in zip(axes, keys, strict=False):
        values = ds[f"{o}_calibrated_pit"].values[window == w]
        values = values[np.isfinite(values)]
        if values.size:
            ax.hist(values, bins=10, range=(0.0, 1.0), color="#4a7fb5", edgecolor="white")
            ax.axhline(values.size / 10, color="black", lw=0.8, ls="--")
        ax.set_title(f"{o}: {w} ({values.size} samples)", fontsize=9)
        ax.set_xlabel("PIT")
    if not keys:
        axes[0].text(0.5, 0.5, "no PIT values", ha="center", va="center")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_correlation(path: Path, ident: Identifiability) -> Path:
    """The posterior correlation matrix of θ* as a colour map with the values written in."""
    n = len(ident.names)
    fig, ax = plt.subplots(figsize=(1.0 + 0.8 * n, 0.6 + 0.7 * n))
    image = ax.imshow(ident.correlation, vmin=-1.0, vmax=1.0, cmap="RdBu_r")
    ax.set_xticks(range(n), ident.names, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(n), ident.names, fontsize=8)
    for i in range(n):
        for j in range(n):
            ax.text(j, i, f"{ident.correlation[i, j]:.2f}", ha="center", va="center", fontsize=7)
    fig.colorbar(image, ax=ax, shrink=0.8)
    fig.tight_layout()
    return save_figure(fig, path)


def uncertainty_figures(
    posterior: Posterior, ds: xr.Dataset, outputs: Sequence[str], folder: Path
) -> list[tuple[str, str, Path]]:
    """``(title, caption, path)`` of the section's figures."""
    ident = identifiability(posterior)
    return [
        (
            "Posterior correlation of θ*",
            "Strong correlations mark combinations the data fix while the parts stay open.",
            plot_correlation(folder / "correlation.png", ident),
        ),
        (
            "PIT histograms",
            "Predictive CDF at each measured sample: a flat histogram (dashed line) means the "
            "bands hold their stated probability; a U shape, bands too narrow; a hump, too wide.",
            plot_pit(folder / "pit.png", ds, outputs),
        ),
    ]


def uncertainty_section(
    posterior: Posterior,
    ds: xr.Dataset,
    outputs: Sequence[str],
    table: Callable[[Sequence[str], list[list[object]]], str],
) -> str:
    """The section's HTML (``table`` renders a header and rows as the report does)."""
    parts = [f'<p class="note">{escape(BAND_TEXT)}</p>']
    sds = posterior.noise_sd()
    if posterior.noise:
        rows: list[list[object]] = []
        for o in posterior.noise:
            sd = sds[o.name].reshape(-1)
            low, high = np.percentile(sd, [2.5, 97.5])
            error = ds.attrs.get(f"{o.name}_calibrated_mc_error", float("nan"))
            in_band = ds.attrs.get(f"{o.name}_calibrated_noise_sd")
            rows.append(
                [
                    o.name,
                    o.model
                    + (
                        " + in-likelihood discrepancy "
                        f"({DISCREPANCY_KINDS.get(str(o.discrepancy), str(o.discrepancy))})"
                        if o.discrepancy
                        else ""
                    ),
                    f"{np.mean(sd):.4g} {o.unit}",
                    f"[{low:.4g}, {high:.4g}]",
                    "–" if in_band is None else f"{float(in_band):.4g} {o.unit}",
                    f"{100 * float(error):.2g} %",
                ]
            )
        header = [
            "output",
            "error model",
            "noise SD",
            "95 % interval",
            "noise SD in the bands",
            "band edge MC error",
        ]
        parts.append(table(header, rows))
        parts.append(f'<p class="note">{escape(NOISE_TEXT)}</p>')
    ident = identifiability(posterior)
    items = "".join(f"<li>{escape(line)}</li>" for line in ident.lines())
    parts.append(
        "<p>Principal directions of the posterior relative to the prior (log scale for "
        f"positive parameters):</p><ul>{items}</ul>"
    )
    rows = [[n, f"{100 * c:.0f} %"] for n, c in zip(ident.names, ident.contraction, strict=True)]
    parts.append(table(["parameter", "prior-to-posterior contraction"], rows))
    return "".join(parts)
