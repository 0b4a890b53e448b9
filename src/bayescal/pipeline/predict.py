"""Calibrated predictions with bands, and fit metrics on the training and test windows.

Predictions come from the emulator at posterior draws of theta* (thinned evenly
over all chains). For draw ``s`` and period ``i`` the emulator gives a mean
``mu_s`` and a variance ``v_s`` (interpolation uncertainty of the weights plus
the out-of-basis variance ``1/lambda``); the observation noise adds
``sd^2 / lambda*_s`` (``sd`` the point-wise standardisation). One realisation
``mu_s + sqrt(v_s + sd^2/lambda*_s) z`` per draw and sample gives the
predictive distribution of a measurement; the band is its central ``level``
interval and the prediction line the mean of ``mu_s``. With a discrepancy, the
corrected prediction adds ``Delta(x)`` (its GP mean and variance) and uses the
theta* draws of the discrepancy phase.

With ``[predict] method = "simulator"`` the simulator itself is re-run at
``runs`` posterior draws instead (:func:`simulator_band`): the prediction is
the mean of those runs and the band adds the same observation noise (and
Delta). This avoids the emulator's extrapolation where the test periods' conditions
``x`` lie outside those of the training periods. The corrected prediction
(model + Delta) always uses the emulator: Delta is estimated as the
observation minus the emulator's prediction of the model, so it also absorbs
the emulator's own error and must be added to that prediction.

Samples of the training periods get the training predictions; samples of the
test window get the predictions of the periods covering it. Everything else
(warm-up, dropped periods) is NaN.

Metrics (see :mod:`bayescal.metrics`) are computed on the samples of the
training periods (``window = "train"``) and of the test window (``"test"``)
where the measurement is finite; ``coverage95`` is the fraction of measured
samples inside the band. ``guideline14`` says whether the ASHRAE Guideline 14
criteria for hourly data hold (CV(RMSE) <= 30 %, |NMBE| <= 10 %); they were
written for whole-building energy use and are shown for orientation only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np
import pandas as pd
import xarray as xr

from bayescal.calibration.posterior import Posterior
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.glossary import GLOSSARY
from bayescal.metrics import (
    KEY_COLUMNS,
    MODELS,
    fit_metrics,
    meets_guideline14,
    metric_columns,
    monthly_metrics,
)
from bayescal.periods import PeriodLayout

__all__ = [
    "Band",
    "DiscrepancyModel",
    "metrics_table",
    "predict_band",
    "predictions_dataset",
    "simulator_band",
]

PAIRS_PER_CHUNK = 20_000


class DiscrepancyModel(Protocol):
    """What predictions need of a fitted difference process."""

    def predict(self, x_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of Delta, ``(N, q)`` each, physical units."""
        ...


@dataclass(frozen=True)
class Band:
    """A prediction over the record: output name -> series ``(n_total,)``."""

    mean: dict[str, np.ndarray]
    lower: dict[str, np.ndarray]
    upper: dict[str, np.ndarray]


def _thin(posterior: Posterior, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` draws spread evenly over all chains: theta* ``(n, t)`` and lambda* ``(n,)``."""
    theta = posterior.draws.reshape(-1, len(posterior.names))
    lam_star = posterior.lam_star.reshape(-1)
    pick = np.unique(np.linspace(0, theta.shape[0] - 1, min(n, theta.shape[0])).astype(int))
    return theta[pick], lam_star[pick]


def _period_moments(
    emulator: Emulator,
    theta: np.ndarray,
    lam_star: np.ndarray,
    x: np.ndarray,
    rng: np.random.Generator,
    discrepancy: DiscrepancyModel | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(N, P)`` and realisations ``(S, N, P)`` of measurements at ``P`` periods."""
    s, p = theta.shape[0], x.shape[0]
    th = np.repeat(theta, p, axis=0)
    xx = np.tile(x, (s, 1))
    # Chunks of whole draws keep the (pairs x runs) work arrays to ~100 MB.
    per = max(1, PAIRS_PER_CHUNK // p) * p
    parts = [emulator.predict(th[i : i + per], xx[i : i + per]) for i in range(0, s * p, per)]
    mean = np.concatenate([m for m, _ in parts], axis=1)  # (N, S P)
    var = np.concatenate([v for _, v in parts], axis=1)
    n = mean.shape[0]
    mean = mean.reshape(n, s, p).transpose(1, 0, 2)
    var = var.reshape(n, s, p).transpose(1, 0, 2)
    sd = emulator.outputs.sd
    var = var + (sd * sd)[None, :, None] / lam_star[:, None, None]
    if discrepancy is not None:
        d_mean, d_var = discrepancy.predict(x)
        mean = mean + d_mean[None]
        var = var + d_var[None]
    real = mean + np.sqrt(var) * rng.standard_normal(mean.shape)
    return mean.mean(axis=0), real


def _place(
    layout: PeriodLayout, starts: np.ndarray, values: np.ndarray, out: np.ndarray, begin: int
) -> None:
    """Write period columns ``values`` ``(n, P)`` into ``out`` at samples >= ``begin``."""
    for i, start in enumerate(starts):
        idx = start + np.arange(layout.period)
        keep = idx >= begin
        out[idx[keep]] = values[keep, i]


def predict_band(
    emulator: Emulator,
    assembled: Assembled,
    posterior: Posterior,
    *,
    draws: int = 300,
    level: float = 0.95,
    seed: int = 0,
    discrepancy: DiscrepancyModel | None = None,
) -> Band:
    """Calibrated prediction of every output over the record, with a band.

    Parameters
    ----------
    emulator, assembled
        The trained emulator and the assembled data (periods, ``x``, ``x_test``).
    posterior
        theta* and lambda* draws.
    draws
        Posterior draws propagated (thinned evenly over the chains).
    level
        Probability of the band. [-]
    seed
        Seed of the realisations that give the band.
    discrepancy
        A fitted difference process to add (``None``: the model alone).

    Returns
    -------
    Band
        NaN outside the training periods and the test window.
    """
    rng = np.random.default_rng([seed, 7])
    theta, lam_star = _thin(posterior, draws)
    layout = assembled.layout
    parts = [(assembled.x, layout.train_starts, 0)]
    if layout.test_starts.size:
        parts.append((assembled.x_test, layout.test_starts, layout.test_begin))
    tail = 50.0 * (1.0 - level)
    slices = emulator.outputs.slices
    out = {k: {n: np.full(layout.n_total, np.nan) for n in slices} for k in ("m", "lo", "hi")}
    for x, starts, begin in parts:
        if not len(starts):
            continue
        mean, real = _period_moments(emulator, theta, lam_star, x, rng, discrepancy)
        lo, hi = np.percentile(real, [tail, 100.0 - tail], axis=0)
        for name, sl in slices.items():
            _place(layout, starts, mean[sl], out["m"][name], begin)
            _place(layout, starts, lo[sl], out["lo"][name], begin)
            _place(layout, starts, hi[sl], out["hi"][name], begin)
    return Band(out["m"], out["lo"], out["hi"])


def _phase_sd(assembled: Assembled, name: str) -> np.ndarray:
    """Standardisation SD of output ``name`` at every sample, by its position in the period."""
    layout = assembled.layout
    sl = assembled.outputs.slices[name]
    sd = assembled.outputs.sd[sl]
    anchor = int(layout.test_starts[0]) if layout.test_starts.size else int(layout.train_starts[0])
    return np.asarray(sd[(np.arange(layout.n_total) - anchor) % layout.period])


def simulator_band(
    assembled: Assembled,
    runs: Mapping[str, np.ndarray],
    lam_star: np.ndarray,
    *,
    level: float = 0.95,
    seed: int = 0,
    discrepancy: DiscrepancyModel | None = None,
) -> Band:
    """Calibrated prediction from simulator runs at posterior draws, with a band.

    Parameters
    ----------
    assembled
        The assembled data (layout, standardisation; ``x`` for a discrepancy).
    runs
        Output name -> simulated series at ``S`` posterior draws ``(S, n_total)``.
    lam_star
        lambda* of the same draws ``(S,)``; the noise variance is ``sd^2 / lambda*``.
    level
        Probability of the band. [-]
    seed
        Seed of the noise realisations.
    discrepancy
        A fitted difference process to add (its mean and variance).

    Returns
    -------
    Band
        NaN outside the training periods and the test window.
    """
    rng = np.random.default_rng([seed, 11])
    layout = assembled.layout
    tail = 50.0 * (1.0 - level)
    covered = np.zeros(layout.n_total, dtype=bool)
    for start in layout.train_starts:
        covered[start : start + layout.period] = True
    covered[layout.test_begin :] = True
    delta_mean = delta_var = None
    if discrepancy is not None:
        names = list(assembled.outputs.names)
        delta_mean = delta_series(assembled, discrepancy, names)
        delta_var = delta_series(assembled, discrepancy, names, variance=True)
    band = Band({}, {}, {})
    for name, sims in runs.items():
        var = _phase_sd(assembled, name) ** 2 / np.asarray(lam_star)[:, None]
        mean = np.asarray(sims, dtype=float)
        if delta_mean is not None and delta_var is not None:
            mean = mean + delta_mean[name][None]
            var = var + delta_var[name][None]
        real = mean + np.sqrt(var) * rng.standard_normal(mean.shape)
        lo, hi = np.percentile(real, [tail, 100.0 - tail], axis=0)
        for target, values in ((band.mean, mean.mean(axis=0)), (band.lower, lo), (band.upper, hi)):
            target[name] = np.where(covered, values, np.nan)
    return band


def delta_series(
    assembled: Assembled,
    discrepancy: DiscrepancyModel,
    names: Sequence[str],
    *,
    variance: bool = False,
) -> dict[str, np.ndarray]:
    """The discrepancy's mean (or variance) over the training periods and the test window."""
    layout = assembled.layout
    out = {n: np.full(layout.n_total, np.nan) for n in names}
    slices = dict(zip(names, _slices(assembled), strict=True))
    parts = [(assembled.x, layout.train_starts, 0)]
    if layout.test_starts.size:
        parts.append((assembled.x_test, layout.test_starts, layout.test_begin))
    for x, starts, begin in parts:
        if len(starts):
            mean, var = discrepancy.predict(x)
            values = var if variance else mean
            for name, sl in slices.items():
                _place(layout, starts, values[sl], out[name], begin)
    return out


def _slices(assembled: Assembled) -> list[slice]:
    return list(assembled.outputs.slices.values())


def windows(layout: PeriodLayout) -> np.ndarray:
    """Label of every sample: ``warmup``, ``train``, ``test`` or ``unused``."""
    label = np.full(layout.n_total, "unused", dtype=object)
    first = int(layout.train_starts.min()) if layout.m_star else layout.warmup
    label[:first] = "warmup"
    for start in layout.train_starts:
        label[start : start + layout.period] = "train"
    label[layout.test_begin :] = "test"
    return label.astype(str)


_SERIES = {
    "measured": "measured {what}",
    "nominal": "{what} simulated at the nominal parameters",
    "calibrated": "calibrated prediction of {what}: mean over posterior draws",
    "calibrated_lower": "lower bound of the band of the calibrated prediction of {what}",
    "calibrated_upper": "upper bound of the band of the calibrated prediction of {what}",
    "delta": "discrepancy Delta = observation - model of {what} (mean)",
    "corrected": "calibrated prediction of {what} corrected by Delta",
    "corrected_lower": "lower bound of the band of the corrected prediction of {what}",
    "corrected_upper": "upper bound of the band of the corrected prediction of {what}",
}
_WINDOW = "part of the record: warmup, train (training periods), test (test window) or unused"


def predictions_dataset(
    times: np.ndarray,
    layout: PeriodLayout,
    measured: Mapping[str, np.ndarray],
    nominal: Mapping[str, np.ndarray],
    calibrated: Band,
    boundary: Mapping[str, np.ndarray],
    corrected: Band | None = None,
    delta: Mapping[str, np.ndarray] | None = None,
    attrs: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """Measured, nominal, calibrated (and corrected) series on the study clock.

    Variables ``{o}_measured``, ``{o}_nominal``, ``{o}_calibrated``,
    ``{o}_calibrated_lower``/``_upper`` and, with a discrepancy, ``{o}_delta``,
    ``{o}_corrected``, ``{o}_corrected_lower``/``_upper``; boundary conditions
    as ``bc_{name}``. Coordinates ``time`` (UTC) and ``window``.
    """
    data: dict[str, Any] = {}
    for o in measured:
        unit = GLOSSARY[o].unit if o in GLOSSARY else ""
        what = f"{o} ({GLOSSARY[o].description})" if o in GLOSSARY else o
        series = {
            "measured": measured[o],
            "nominal": nominal[o],
            "calibrated": calibrated.mean[o],
            "calibrated_lower": calibrated.lower[o],
            "calibrated_upper": calibrated.upper[o],
        }
        if corrected is not None and delta is not None:
            series |= {
                "delta": delta[o],
                "corrected": corrected.mean[o],
                "corrected_lower": corrected.lower[o],
                "corrected_upper": corrected.upper[o],
            }
        for kind, values in series.items():
            text = _SERIES[kind].format(what=what)
            attrs = {"units": unit, "long_name": f"{o} {kind}", "description": text}
            data[f"{o}_{kind}"] = ("time", np.asarray(values, dtype=float), attrs)
    for b, values in boundary.items():
        unit = GLOSSARY[b].unit if b in GLOSSARY else ""
        text = f"boundary condition {b}" + (f": {GLOSSARY[b].description}" if b in GLOSSARY else "")
        attrs = {"units": unit, "long_name": b, "description": text}
        data[f"bc_{b}"] = ("time", np.asarray(values, dtype=float), attrs)
    coords = {
        "time": ("time", np.asarray(times).astype("datetime64[ns]"), {"description": "UTC"}),
        "window": ("time", windows(layout), {"description": _WINDOW}),
    }
    meta = {"outputs": ",".join(measured), "boundary": ",".join(boundary)}
    return xr.Dataset(data, coords=coords, attrs=meta | dict(attrs or {}))


def _window_mask(ds: xr.Dataset, window: str) -> np.ndarray:
    return np.asarray(ds["window"].values == window)


def _monthly_how(output: str) -> Literal["sum", "mean"]:
    """Monthly totals for energies (meters), monthly means for anything else."""
    quantity = GLOSSARY.get(output)
    return "sum" if quantity is not None and quantity.dimension == "energy" else "mean"


def metrics_table(ds: xr.Dataset) -> pd.DataFrame:
    """Fit metrics per output, model and window (see the module docstring)."""
    rows = []
    for o in ds.attrs["outputs"].split(","):
        obs = ds[f"{o}_measured"].values
        for model in MODELS:
            key = {"nominal": "nominal", "calibrated": "calibrated"}.get(model, "corrected")
            if f"{o}_{key}" not in ds:
                continue
            sim = ds[f"{o}_{key}"].values
            for window in ("train", "test"):
                mask = _window_mask(ds, window) & np.isfinite(sim)
                if not mask.any():
                    continue
                m = fit_metrics(sim[mask], obs[mask]).as_dict()
                m["coverage95"] = float("nan")
                if model != "nominal":
                    lo = ds[f"{o}_{key}_lower"].values[mask]
                    hi = ds[f"{o}_{key}_upper"].values[mask]
                    ok = np.isfinite(obs[mask])
                    inside = (obs[mask] >= lo) & (obs[mask] <= hi)
                    m["coverage95"] = float(np.mean(inside[ok])) if ok.any() else float("nan")
                m["guideline14"] = meets_guideline14(m["cv_rmse"], m["nmbe"])
                times = ds["time"].values[mask]
                m |= monthly_metrics(times, sim[mask], obs[mask], how=_monthly_how(o))
                rows.append({"output": o, "model": model, "window": window} | m)
    columns = [*KEY_COLUMNS, *(c.name for c in metric_columns("csv"))]
    return pd.DataFrame(rows, columns=columns)
