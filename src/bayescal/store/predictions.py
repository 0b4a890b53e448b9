"""The predictions of a study: ``predictions.nc`` and ``metrics.csv``.

``predictions.nc`` holds the measured, nominal, calibrated (and corrected)
series on the study clock with their bands and the boundary conditions
(:func:`bayescal.pipeline.predict.predictions_dataset`); every series carries
``units`` (its output's unit, :mod:`bayescal.glossary`), ``long_name`` and
``description``. ``metrics.csv`` is the table of fit metrics per output, model
and window (columns: :data:`bayescal.metrics.METRIC_COLUMNS`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Final

import pandas as pd
import xarray as xr

from bayescal.atomic import atomic_write, atomic_write_text

__all__ = ["FILES", "METRICS_FILE", "SERIES_FILE", "load_predictions", "save_predictions"]

#: File names in a study's output folder.
SERIES_FILE: Final = "predictions.nc"
METRICS_FILE: Final = "metrics.csv"
FILES: Final = (SERIES_FILE, METRICS_FILE)


def save_predictions(
    folder: str | os.PathLike[str], dataset: xr.Dataset, metrics: pd.DataFrame
) -> list[str]:
    """Write the series (netCDF) and the metrics (CSV) into ``folder`` atomically.

    Returns
    -------
    list of str
        The names of the files written (relative to ``folder``).
    """
    out = Path(folder)

    def write(stream: Any) -> None:
        stream.write(dataset.to_netcdf())

    atomic_write(out / SERIES_FILE, write)
    atomic_write_text(out / METRICS_FILE, metrics.to_csv(index=False))
    return list(FILES)


def load_predictions(folder: str | os.PathLike[str]) -> tuple[xr.Dataset, pd.DataFrame]:
    """Read the series and the metrics written by :func:`save_predictions`."""
    out = Path(folder)
    with xr.open_dataset(out / SERIES_FILE) as ds:
        dataset = ds.load()
    return dataset, pd.read_csv(out / METRICS_FILE)
