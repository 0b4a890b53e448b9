"""A predictions dataset with Gaussian bands around a zero prediction (test helper).

``metrics_table`` reads it as ``bayescal run`` writes ``predictions.nc``: output
``y`` measured as the given errors, a nominal prediction of 1 and a calibrated one
of 0 with 95 % (``level``) and 50 % bands of a Gaussian with SD ``band_sd``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import xarray as xr
from scipy.stats import norm


def band_dataset(
    errors: np.ndarray,
    band_sd: float,
    *,
    level: float = 0.95,
    freq: str = "10min",
    test: int = 0,
) -> xr.Dataset:
    """``errors`` as the measurements; the last ``test`` samples form the test window."""
    n = errors.size
    zero = np.zeros(n)
    z_outer, z50 = norm.ppf(0.5 + 0.5 * level), norm.ppf(0.75)
    series = {
        "measured": errors,
        "nominal": zero + 1.0,
        "calibrated": zero,
        "calibrated_lower": zero - z_outer * band_sd,
        "calibrated_upper": zero + z_outer * band_sd,
        "calibrated_lower50": zero - z50 * band_sd,
        "calibrated_upper50": zero + z50 * band_sd,
    }
    data = {f"y_{k}": ("time", v) for k, v in series.items()}
    times = pd.date_range("2013-03-01", periods=n, freq=freq).values
    window = np.where(np.arange(n) < n - test, "train", "test")
    coords = {"time": times, "window": ("time", window)}
    return xr.Dataset(data, coords=coords, attrs={"outputs": "y", "level": level})
