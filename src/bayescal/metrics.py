"""Goodness-of-fit metrics of a simulated (or predicted) series against measurements.

Definitions (``e = simulated - measured``, over the ``n`` scored samples):

* MSE = mean(e²); RMSE = sqrt(MSE);
* mean absolute error = mean(|e|);
* maximum absolute error = max(|e|) (the paper's "MAE" column is this one);
* bias = mean(e);
* excess kurtosis = mean((e - bias)⁴) / var(e)² - 3 (0 for Gaussian errors; large
  when a few errors dominate the spread: a Gaussian band matched to their variance
  is then too wide in its middle and its 50 % band holds more than half of them);
* ASHRAE Guideline 14 CV(RMSE) = sqrt(sum(e²) / (n - p)) / mean(measured) and
  NMBE = sum(-e) / ((n - p) · mean(measured)), both in %, with ``p`` the number of
  parameters of the model (degrees of freedom; Guideline 14 uses p = 1 for
  calibrated simulation). NMBE is positive when the model under-predicts.
  Both are undefined (NaN) where the measured mean is zero; CV(RMSE) divides by
  the absolute mean, so it stays positive for series with a negative mean (a
  heat flux out of a room).

The prediction stage adds ``coverage95`` and ``coverage50`` (shares of measured
samples inside the 95 % and 50 % bands of the predictive distribution; honest
bands give about 0.95 and 0.50), ``pit_ks`` (the largest distance between the
empirical distribution of the PIT values and the uniform one: small when the
predictive distribution is right), ``band_scale`` (the outer band's spread over the
errors' RMS: the band's half-width divided by the normal quantile of its level,
median over the samples, over the RMSE; about 1 when the band's width matches the
errors, above 1 when it is wider than the errors it should hold) and
``guideline14`` (:func:`meets_guideline14`), and ``n_eff95`` and ``n_eff50``
(:func:`coverage_n_eff`: how many independent samples the coverage of an honest
band is worth on the window, fewer than ``n`` where the errors are
autocorrelated). :func:`band_notes` turns these into sentences where a band's
width or the errors' shape explains a coverage off its rate, and where a
coverage off its rate is, or is not, within what one window gives an honest
band (:func:`honest_range`).

How much a coverage says
------------------------
A coverage is measured on one window, and on a time series the samples are
not independent: an hour that falls outside the band is often followed by
another. :func:`coverage_n_eff` asks what an honest band would show: its
errors, standardised, are N(0, 1) with the autocorrelation ``r_k`` that the
window's standardised errors have (estimated from the normal scores of their
ranks, so that a few large errors do not set it; lags truncated by Geyer's
initial positive sequence). Two samples ``k`` apart are then both
inside the central band of level ``L`` (``c`` = the normal quantile of
``(1 + L) / 2``) with probability ``1 - 4 T(c, a) - 4 T(c, 1 / a)``,
``a = sqrt((1 - r_k) / (1 + r_k))`` and ``T`` Owen's T function (the
bivariate normal's square), which gives the covariance ``C_k`` of their
indicators; the variance of the coverage over ``n`` samples with ``n_k``
pairs at lag ``k`` is ``(n L (1 - L) + 2 sum_k n_k C_k) / n²``, and
``n_eff = L (1 - L) / variance`` (``n`` for independent samples).
:func:`honest_range` is the central 95 % of a binomial share with ``n_eff``
trials: the coverages an honest band shows on such a window 95 % of the
time.

Guideline 14 by resolution
--------------------------
Guideline 14 gives criteria for two resolutions of the data: hourly
(CV(RMSE) <= 30 %, |NMBE| <= 10 %) and monthly (CV(RMSE) <= 15 %,
|NMBE| <= 5 %). ``guideline14`` applies the hourly criteria to the series on
the study clock (hourly or finer; Guideline 14 has no daily criteria, and the
hourly ones are the ones used for daily data too). :func:`monthly_metrics`
adds the monthly criteria: the scored samples are gathered into calendar
months (of the UTC timestamps) and each month's values are added up (energies,
``how="sum"``: the monthly totals a bill shows) or averaged (any other
quantity), measured and simulated over the same samples; CV(RMSE) and NMBE
then use the ``n`` months, again with ``n - p`` (p = 1) in the denominators,
so at least two months are needed.

:data:`METRIC_COLUMNS` is the one list of metric columns: their names (the
columns of ``metrics.csv``), labels, units and descriptions. Every table of
metrics (``metrics.csv``, the report, ``bayescal show``, ``bayescal
simulate``) takes its columns from it through :func:`metric_columns`; adding a
metric means adding it here (and computing it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Final, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy import stats
from scipy.special import owens_t

__all__ = [
    "G14_CV_RMSE",
    "G14_MONTHLY_CV_RMSE",
    "G14_MONTHLY_NMBE",
    "G14_NMBE",
    "KEY_COLUMNS",
    "METRIC_COLUMNS",
    "MODELS",
    "MetricColumn",
    "Metrics",
    "band_notes",
    "coverage_n_eff",
    "coverage_n_effs",
    "fit_metrics",
    "honest_range",
    "meets_guideline14",
    "metric_columns",
    "monthly_metrics",
]

#: ASHRAE Guideline 14 (2014) calibration criteria for hourly data: CV(RMSE) <= 30 %
#: and |NMBE| <= 10 % (both with p = 1 degree of freedom).
G14_CV_RMSE: Final = 30.0
G14_NMBE: Final = 10.0
#: ASHRAE Guideline 14 (2014) calibration criteria for monthly data: CV(RMSE) <= 15 %
#: and |NMBE| <= 5 %.
G14_MONTHLY_CV_RMSE: Final = 15.0
G14_MONTHLY_NMBE: Final = 5.0
#: :func:`band_notes`: a band whose spread is outside ``[1 / BAND_SCALE_OFF,
#: BAND_SCALE_OFF]`` times the errors' RMS is called wider / narrower than the errors.
BAND_SCALE_OFF: Final = 1.25
#: :func:`band_notes`: errors with a larger excess kurtosis are called heavy-tailed
#: (Gaussian errors: 0, with a standard error of about sqrt(24 / n) for independent ones).
HEAVY_TAILS: Final = 2.0
#: :func:`band_notes`: a coverage this far from its band's rate (outer band, 50 % band)
#: gets a note that says whether one window's chance explains it.
OFF_RATE: Final = (0.02, 0.05)


@dataclass(frozen=True)
class Metrics:
    """Fit metrics; units are the output's (squared for MSE), CV(RMSE) and NMBE in %."""

    n: int
    mse: float
    rmse: float
    mean_abs_error: float
    max_abs_error: float
    bias: float
    cv_rmse: float
    nmbe: float
    excess_kurtosis: float = float("nan")

    def as_dict(self) -> dict[str, float]:
        """The metrics as a plain dictionary."""
        return asdict(self)


def fit_metrics(simulated: npt.ArrayLike, measured: npt.ArrayLike, *, p: int = 1) -> Metrics:
    """Metrics of ``simulated`` against ``measured`` over samples where both are finite.

    Parameters
    ----------
    simulated, measured
        Series of the same shape, in the output's unit.
    p
        Degrees of freedom removed in CV(RMSE) and NMBE (ASHRAE Guideline 14).
    """
    sim = np.asarray(simulated, dtype=float)
    obs = np.asarray(measured, dtype=float)
    if sim.shape != obs.shape:
        raise ValueError(f"simulated has shape {sim.shape}, measured {obs.shape}")
    ok = np.isfinite(sim) & np.isfinite(obs)
    e = sim[ok] - obs[ok]
    n = int(e.size)
    if n == 0:
        nan = float("nan")
        return Metrics(0, nan, nan, nan, nan, nan, nan, nan)
    mse = float(np.mean(e**2))
    mean_obs = float(np.mean(obs[ok]))
    dof = max(n - p, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cv = 100.0 * np.sqrt(np.sum(e**2) / dof) / abs(mean_obs) if mean_obs != 0 else float("nan")
        nmbe = 100.0 * float(np.sum(-e)) / (dof * mean_obs) if mean_obs != 0 else float("nan")
    spread = n >= 4 and float(np.var(e)) > 0
    excess = float(stats.kurtosis(e)) if spread else float("nan")  # Fisher, as defined above
    return Metrics(
        n=n,
        mse=mse,
        rmse=float(np.sqrt(mse)),
        mean_abs_error=float(np.mean(np.abs(e))),
        max_abs_error=float(np.max(np.abs(e))),
        bias=float(np.mean(e)),
        cv_rmse=float(cv),
        nmbe=float(nmbe),
        excess_kurtosis=excess,
    )


def meets_guideline14(
    cv_rmse: float, nmbe: float, resolution: Literal["hourly", "monthly"] = "hourly"
) -> bool:
    """Whether the ASHRAE Guideline 14 criteria of a data resolution hold.

    Hourly: CV(RMSE) <= 30 % and |NMBE| <= 10 %; monthly: CV(RMSE) <= 15 % and
    |NMBE| <= 5 %. Written for whole-building energy use; shown for
    orientation on other quantities. False where either is NaN.
    """
    if resolution == "monthly":
        return bool(abs(cv_rmse) <= G14_MONTHLY_CV_RMSE and abs(nmbe) <= G14_MONTHLY_NMBE)
    return bool(abs(cv_rmse) <= G14_CV_RMSE and abs(nmbe) <= G14_NMBE)


def monthly_metrics(
    times: npt.ArrayLike,
    simulated: npt.ArrayLike,
    measured: npt.ArrayLike,
    *,
    how: Literal["sum", "mean"] = "sum",
    p: int = 1,
) -> dict[str, float | bool]:
    """Guideline 14's monthly CV(RMSE) and NMBE of a series (see the module notes).

    Parameters
    ----------
    times
        Sample instants (``datetime64``, UTC), shape ``(n,)``.
    simulated, measured
        Series of the same shape, in the output's unit.
    how
        ``"sum"``: monthly totals (energies); ``"mean"``: monthly means.
    p
        Degrees of freedom removed in the denominators.

    Returns
    -------
    dict
        ``n_months``; ``cv_rmse_monthly`` and ``nmbe_monthly`` [%] (NaN with
        fewer than ``p + 1`` months); ``guideline14_monthly`` (NaN where
        undefined, else whether CV(RMSE) <= 15 % and |NMBE| <= 5 %).
    """
    t = np.asarray(times).astype("datetime64[M]")
    sim = np.asarray(simulated, dtype=float)
    obs = np.asarray(measured, dtype=float)
    ok = np.isfinite(sim) & np.isfinite(obs)
    months, slot = np.unique(t[ok], return_inverse=True)
    count = np.bincount(slot, minlength=months.size).astype(float)
    sim_m = np.bincount(slot, weights=sim[ok], minlength=months.size)
    obs_m = np.bincount(slot, weights=obs[ok], minlength=months.size)
    if how == "mean" and months.size:
        sim_m, obs_m = sim_m / count, obs_m / count
    nan = float("nan")
    if months.size < p + 1:
        return {
            "n_months": int(months.size),
            "cv_rmse_monthly": nan,
            "nmbe_monthly": nan,
            "guideline14_monthly": nan,
        }
    m = fit_metrics(sim_m, obs_m, p=p)
    defined = bool(np.isfinite(m.cv_rmse) and np.isfinite(m.nmbe))
    return {
        "n_months": int(months.size),
        "cv_rmse_monthly": m.cv_rmse,
        "nmbe_monthly": m.nmbe,
        "guideline14_monthly": meets_guideline14(m.cv_rmse, m.nmbe, "monthly") if defined else nan,
    }


Table = Literal["csv", "show", "report", "simulate"]


@dataclass(frozen=True)
class MetricColumn:
    """One column of the metric tables.

    Attributes
    ----------
    name
        Column of ``metrics.csv`` (a field of :class:`Metrics`, ``coverage95``
        or ``guideline14``).
    label
        Short label of the plain-text table of ``bayescal simulate``.
    title
        Header in the report; ``{u}`` stands for the output's unit, ``{u2}`` for its square.
    unit
        Unit in words: ``"{u}"`` (the output's), ``"{u2}"``, ``"%"``, ``"1"``
        (a fraction) or ``""`` (a count or a yes/no).
    description
        What the column holds.
    kind
        ``"count"``, ``"number"`` or ``"flag"`` (how a table writes the value).
    scale
        Factor applied in the report (a fraction shown in %).
    width, digits
        Width and significant digits in the plain-text table of ``bayescal simulate``.
    """

    name: str
    label: str
    title: str
    unit: str
    description: str
    kind: Literal["count", "number", "flag"] = "number"
    scale: float = 1.0
    width: int = 10
    digits: int = 4


#: Every metric column, in the order of ``metrics.csv``.
METRIC_COLUMNS: Final = (
    MetricColumn(
        "n", "n", "n", "", "samples scored (measured and predicted finite)", "count", width=6
    ),
    MetricColumn("mse", "MSE", "MSE [{u2}]", "{u2}", "mean squared error", width=11),
    MetricColumn("rmse", "RMSE", "RMSE [{u}]", "{u}", "root mean squared error"),
    MetricColumn("mean_abs_error", "mean|e|", "mean abs error [{u}]", "{u}", "mean absolute error"),
    MetricColumn(
        "max_abs_error",
        "max|e|",
        "max abs error [{u}]",
        "{u}",
        "maximum absolute error (the paper's 'MAE')",
    ),
    MetricColumn("bias", "bias", "bias [{u}]", "{u}", "mean error, predicted - measured", digits=3),
    MetricColumn(
        "cv_rmse",
        "CV(RMSE)%",
        "CV(RMSE) [%]",
        "%",
        "coefficient of variation of the RMSE (ASHRAE Guideline 14, p = 1)",
        width=11,
        digits=3,
    ),
    MetricColumn(
        "nmbe",
        "NMBE%",
        "NMBE [%]",
        "%",
        "normalised mean bias error (ASHRAE Guideline 14, p = 1); > 0 when the "
        "model under-predicts",
        width=8,
        digits=3,
    ),
    MetricColumn(
        "coverage95",
        "cover95",
        "coverage of 95 % band [%]",
        "1",
        "share of the measured samples inside the 95 % band",
        scale=100.0,
    ),
    MetricColumn(
        "coverage50",
        "cover50",
        "coverage of 50 % band [%]",
        "1",
        "share of the measured samples inside the 50 % band",
        scale=100.0,
    ),
    MetricColumn(
        "n_eff95",
        "neff95",
        "independent samples (95 % band)",
        "",
        "how many independent samples the outer band's coverage is worth on this window: "
        "the samples' count where the errors are uncorrelated, fewer where they are not "
        "(an honest band covers honest_range(level, n_eff95) of them)",
        digits=3,
    ),
    MetricColumn(
        "n_eff50",
        "neff50",
        "independent samples (50 % band)",
        "",
        "the same for the 50 % band's coverage",
        digits=3,
    ),
    MetricColumn(
        "pit_ks",
        "PIT KS",
        "PIT distance from uniform",
        "1",
        "largest gap between the PIT values' distribution and the uniform one "
        "(Kolmogorov-Smirnov distance; residuals are autocorrelated, so no p-value)",
        digits=3,
    ),
    MetricColumn(
        "band_scale",
        "bandSD/e",
        "band spread / RMSE",
        "1",
        "the outer band's half-width over the normal quantile of its level (median over "
        "the samples), divided by the RMSE: about 1 when the band is as wide as the errors",
        digits=3,
    ),
    MetricColumn(
        "excess_kurtosis",
        "kurt",
        "excess kurtosis of the errors",
        "1",
        "excess kurtosis of the errors (0 for Gaussian ones; large when a few errors "
        "dominate their spread)",
        digits=3,
    ),
    MetricColumn(
        "guideline14",
        "G14",
        "meets Guideline 14",
        "",
        "CV(RMSE) <= 30 % and |NMBE| <= 10 % (ASHRAE Guideline 14, hourly)",
        "flag",
    ),
    MetricColumn(
        "n_months", "months", "months", "", "calendar months holding scored samples", "count"
    ),
    MetricColumn(
        "cv_rmse_monthly",
        "CVm%",
        "monthly CV(RMSE) [%]",
        "%",
        "CV(RMSE) of the monthly totals (energies) or means (ASHRAE Guideline 14, n - 1 "
        "months in the denominator); NaN with one month",
        digits=3,
    ),
    MetricColumn(
        "nmbe_monthly",
        "NMBEm%",
        "monthly NMBE [%]",
        "%",
        "NMBE of the monthly totals (energies) or means (ASHRAE Guideline 14, n - 1 months)",
        digits=3,
    ),
    MetricColumn(
        "guideline14_monthly",
        "G14m",
        "meets Guideline 14 (monthly)",
        "",
        "monthly CV(RMSE) <= 15 % and |NMBE| <= 5 % (ASHRAE Guideline 14, monthly)",
        "flag",
    ),
)

#: Columns that say which row a metric belongs to (before the metrics in ``metrics.csv``).
KEY_COLUMNS: Final = ("output", "model", "window")
#: The models scored (values of the ``model`` column), in table order.
MODELS: Final = ("nominal", "calibrated", "calibrated+delta")

_ERRORS = ("mse", "rmse", "mean_abs_error", "max_abs_error")
_BANDS = (
    "coverage95",
    "coverage50",
    "n_eff95",
    "pit_ks",
    "band_scale",
    "excess_kurtosis",
    "guideline14",
)
_MONTHLY = ("cv_rmse_monthly", "nmbe_monthly", "guideline14_monthly")
_TABLES: dict[str, tuple[str, ...]] = {
    "csv": tuple(c.name for c in METRIC_COLUMNS),
    "show": (*_ERRORS, "cv_rmse", "nmbe", *_BANDS),
    # the report puts the paper's "MAE" (max abs error) before the mean absolute error
    "report": (
        "n",
        "mse",
        "max_abs_error",
        "mean_abs_error",
        "cv_rmse",
        "nmbe",
        *_BANDS,
        *_MONTHLY,
    ),
    "simulate": ("n", *_ERRORS, "bias", "cv_rmse", "nmbe"),
}


def metric_columns(table: Table = "csv") -> tuple[MetricColumn, ...]:
    """The columns of one table, in its order.

    Parameters
    ----------
    table
        ``"csv"`` (``metrics.csv``, every column), ``"show"`` (``bayescal show``),
        ``"report"`` (the HTML report) or ``"simulate"`` (``bayescal simulate``,
        the metrics of one run).
    """
    by_name = {c.name: c for c in METRIC_COLUMNS}
    return tuple(by_name[name] for name in _TABLES[table])


def coverage_n_eff(
    z: npt.ArrayLike, positions: npt.ArrayLike | None = None, *, level: float = 0.95
) -> float:
    """How many independent samples the coverage of an honest central band is worth.

    See the module notes ("How much a coverage says") for the formula.

    Parameters
    ----------
    z
        The errors standardised by the band (prediction minus measurement over
        the band's spread; any common scale: only their correlation enters),
        shape ``(n,)``; non-finite values are left out.
    positions
        Integer places of the samples on the study clock, shape ``(n,)``,
        increasing: samples ``k`` places apart are pairs at lag ``k`` (a window
        of several periods has gaps); default ``0, 1, ..., n - 1``.
    level
        Probability of the central band, in (0, 1). [-]

    Returns
    -------
    float
        ``n_eff`` in ``[1, n]`` (``n`` for fewer than 3 samples or constant errors).
    """
    return coverage_n_effs(z, positions, levels=(level,))[0]


def coverage_n_effs(
    z: npt.ArrayLike, positions: npt.ArrayLike | None = None, *, levels: Sequence[float]
) -> tuple[float, ...]:
    """:func:`coverage_n_eff` for several band levels, the errors' autocorrelation
    estimated once."""
    for level in levels:
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must lie in (0, 1), got {level}")
    values = np.asarray(z, dtype=float).ravel()
    place = np.arange(values.size) if positions is None else np.asarray(positions).ravel()
    keep = np.isfinite(values)
    values, place = values[keep], place[keep].astype(np.int64)
    n = values.size
    if n < 3 or np.ptp(values) == 0.0:
        return tuple(float(n) for _ in levels)
    pairs, r = _lag_correlations(values, place)
    return tuple(_n_eff(n, pairs, r, level) for level in levels)


def _lag_correlations(
    values: npt.NDArray[np.float64], place: npt.NDArray[np.int64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Pair counts and autocorrelations of the lags up to Geyer's cut (module notes)."""
    n = values.size
    # normal scores of the ranks: the honest band's N(0, 1) errors, robust to a few
    # large ones (whose products would otherwise set every autocorrelation)
    x = stats.norm.ppf(stats.rankdata(values) / (n + 1.0))
    var = float(np.mean(x * x))
    span = int(place.max() - place.min()) + 1
    full, there = np.zeros(span), np.zeros(span)
    full[place - place.min()], there[place - place.min()] = x, 1.0
    size = 1 << int(np.ceil(np.log2(2 * span)))
    fx, fm = np.fft.rfft(full, size), np.fft.rfft(there, size)
    acov = np.fft.irfft(fx * np.conj(fx), size)[:span]
    pairs = np.rint(np.fft.irfft(fm * np.conj(fm), size)[:span])
    lags = np.arange(1, min(span, n // 2 + 1))
    lags = lags[pairs[lags] > 0]
    r = acov[lags] / (pairs[lags] * var)
    # Geyer's initial positive sequence: lags up to the first pair (r_2m + r_2m+1) <= 0
    rho = np.concatenate(([1.0], r))
    sums = rho[0 : rho.size - 1 : 2] + rho[1::2]
    stop = int(np.argmax(sums <= 0.0)) if np.any(sums <= 0.0) else sums.size
    used = slice(0, max(2 * stop - 1, 0))
    return pairs[lags][used], r[used]


def _n_eff(
    n: int, pairs: npt.NDArray[np.float64], r: npt.NDArray[np.float64], level: float
) -> float:
    """``L (1 - L) / var(coverage)`` of the band of ``level`` (module notes)."""
    c = float(stats.norm.ppf(0.5 + 0.5 * level))
    rk = np.clip(r, -1.0 + 1e-12, 1.0 - 1e-12)
    a = np.sqrt((1.0 - rk) / (1.0 + rk))
    both = 1.0 - 4.0 * owens_t(c, a) - 4.0 * owens_t(c, 1.0 / a)
    cov = np.maximum(both - level * level, 0.0)
    single = level * (1.0 - level)
    variance = (n * single + 2.0 * float(np.sum(pairs * cov))) / n**2
    return float(np.clip(single / variance, 1.0, n))


def honest_range(level: float, n_eff: float, *, probability: float = 0.95) -> tuple[float, float]:
    """The coverages an honest band of ``level`` shows on a window worth ``n_eff``
    independent samples, ``probability`` of the time.

    The central ``probability`` of a binomial share with ``round(n_eff)`` trials
    (at least 1) and success probability ``level``.
    """
    m = max(1, round(n_eff))
    tail = 0.5 * (1.0 - probability)
    low = float(stats.binom.ppf(tail, m, level)) / m
    high = float(stats.binom.ppf(1.0 - tail, m, level)) / m
    return low, high


def band_notes(metrics: pd.DataFrame, *, level: float = 0.95) -> list[str]:
    """Sentences saying why a calibrated band's coverage is off its rate, where the
    metrics show it.

    For every row of ``metrics`` (a ``metrics.csv`` table) with bands: a band
    whose spread is more than :data:`BAND_SCALE_OFF` times the errors' RMS (or
    less than its reciprocal) is wider (narrower) than the errors it should
    hold; errors with an excess kurtosis above :data:`HEAVY_TAILS` are
    heavy-tailed, and where the 50 % band then holds more than 55 % of them,
    a few large errors set the Gaussian band's spread while most errors are
    smaller. The thresholds describe; they are not tests (the samples of a
    series are correlated).

    Parameters
    ----------
    metrics
        A table with the columns of ``metrics.csv``.
    level
        Probability of the outer band. [-]
    """
    if "band_scale" not in metrics.columns:  # older runs
        return []
    notes = []
    outer = f"{100 * level:g} %"
    for _, row in metrics.iterrows():
        scale = float(row["band_scale"])
        if not np.isfinite(scale):
            continue
        where = f"{row['output']}, {row['model']}, {row['window']}"
        cover = f"covers {float(row['coverage95']):.3f} / {float(row['coverage50']):.3f}"
        if scale > BAND_SCALE_OFF or scale < 1.0 / BAND_SCALE_OFF:
            side = "wider" if scale > 1.0 else "narrower"
            notes.append(
                f"{where}: the {outer} band's spread is {scale:.2f} times the errors' RMS, "
                f"{side} than the errors it should hold ({cover} at {outer} / 50 %)."
            )
        kurtosis = float(row.get("excess_kurtosis", float("nan")))
        if kurtosis > HEAVY_TAILS and float(row["coverage50"]) > 0.55:
            notes.append(
                f"{where}: the errors are heavy-tailed (excess kurtosis {kurtosis:.3g}): a "
                "few large errors set the spread of the Gaussian band, and its middle half "
                f"holds {float(row['coverage50']):.3f} of them; an error model with heavier "
                "tails, or the cause of the large errors, is what would narrow it."
            )
        notes += _chance_notes(row, where, level)
    return notes


def _chance_notes(row: pd.Series, where: str, level: float) -> list[str]:
    """Notes on coverages more than :data:`OFF_RATE` from their rate: within or outside
    what one window gives an honest band (:func:`honest_range`)."""
    notes = []
    bands = (
        ("coverage95", "n_eff95", level, OFF_RATE[0]),
        ("coverage50", "n_eff50", 0.5, OFF_RATE[1]),
    )
    for column, count, rate, off in bands:
        cover, n_eff = float(row.get(column, np.nan)), float(row.get(count, np.nan))
        if not (np.isfinite(cover) and np.isfinite(n_eff)):
            continue
        low, high = honest_range(rate, n_eff)
        name = f"{100 * rate:g} %"
        samples = f"about {n_eff:.0f} independent samples of {int(row['n'])}"
        if low <= cover <= high and abs(cover - rate) > off:
            notes.append(
                f"{where}: the {name} band covers {cover:.3f}, within {low:.2f}-{high:.2f}, what "
                f"an honest band covers 95 % of the time on a window of {samples}: this "
                "window cannot tell the band from an honest one."
            )
        elif not low <= cover <= high:
            side = "too wide" if cover > high else "too narrow"
            notes.append(
                f"{where}: the {name} band covers {cover:.3f}, outside {low:.2f}-{high:.2f}, "
                f"what an honest band covers 95 % of the time on a window of {samples}: "
                f"the band is {side} for these errors."
            )
    return notes
