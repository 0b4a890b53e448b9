"""Figures a user looks at: measured against simulated series."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from bayescal.atomic import atomic_write
from bayescal.glossary import GLOSSARY


def _label(name: str) -> str:
    q = GLOSSARY.get(name)
    return f"{name} [{q.unit}]" if q else name


def plot_measured_vs_simulated(
    path: Path,
    times: np.ndarray,
    measured: Mapping[str, np.ndarray],
    simulated: Mapping[str, np.ndarray],
    *,
    test_begin: int | None = None,
    warmup_end: int | None = None,
    title: str = "",
) -> Path:
    """Measured and simulated outputs against time, one panel per output, saved as PNG.

    Parameters
    ----------
    path
        PNG file to write (atomically).
    times
        Sample instants (``datetime64``).
    measured, simulated
        Output name -> series.
    test_begin
        First sample of the test window (shaded).
    warmup_end
        First sample after the warm-up (shaded grey before it).
    """
    names = list(measured)
    fig, axes = plt.subplots(len(names), 1, figsize=(11, 3.2 * len(names)), squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        ax.plot(times, measured[name], color="black", lw=0.9, label="measured")
        ax.plot(times, simulated[name], color="tab:red", lw=0.9, label="simulated")
        if warmup_end:
            ax.axvspan(
                times[0], times[min(warmup_end, len(times) - 1)], color="0.9", label="warm-up"
            )
        if test_begin is not None and test_begin < len(times):
            ax.axvspan(times[test_begin], times[-1], color="tab:blue", alpha=0.1, label="test")
        ax.set_ylabel(_label(name))
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8, ncols=4)
    axes[0, 0].set_title(title)
    axes[-1, 0].set_xlabel("time (UTC)")
    fig.autofmt_xdate()
    fig.tight_layout()
    target = atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110))
    plt.close(fig)
    return target
