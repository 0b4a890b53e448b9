"""Known-truth coverage of the calibration's intervals and bands (issue 15's acceptance).

Each experiment calibrates the virtual wall (``helpers/virtual_wall.py``) at
truths drawn inside the paper's priors (``helpers/coverage.py``: 20 training
days, 4 test days, 30 runs, 4 x (1000 + 1000) draws) and checks

* the 95 % intervals of the three parameters cover their truths at a rate
  consistent with 95 %: at least the 1 % quantile of Binomial(n, 0.95)
  (25 of 30 intervals at 10 truths, 4 of 6 at 2);
* the 95 % prediction band covers 0.92-0.98 and the 50 % band 0.45-0.55 of the
  measured samples, averaged over the truths, on the training and test windows;
  with fewer samples (2 truths, a quick check by hand) the range widens to 3.5
  binomial standard errors of the effective number of samples (AR(1) errors:
  ``n (1 - phi) / (1 + phi)``);
* the noise SD's 95 % interval covers what it estimates with white errors (the
  injected noise and the noise-free signal's part outside the basis,
  ``coverage.effective_noise_sd``) at the binomial rate, and with AR(1) errors
  reaches at least the injected noise's SD (an upper estimate); the derived
  quantities' intervals (each on its own) cover theirs at the binomial rate;
* the emulator route's band ([predict] method = "emulator") at the same rates,
  on the training periods and on the test window (the emulator conditioned on
  the design runs over the test window too, and the band holding the
  out-of-basis part the test window adds: method.md section 6).

``make validate`` runs 10 truths per experiment, CI's third job 4
(``BAYESCAL_VALIDATION_TRUTHS``; 2 when the variable is unset). With
``BAYESCAL_VALIDATION_REPORT=FILE`` every case's coverage is appended to FILE
as a JSON line (the numbers of docs/case-studies.md).

Experiments: white noise of SD 0.0837 W/m² with the white error model (the
paper's case); AR(1) noise (lag-1 correlation 0.8) with the AR(1) model; the
white model on that AR(1) noise, which must *fail* (coverage below the bound:
it takes 48 correlated samples a day for 48 independent ones); and a model-form
error of the observation: the "logger" records half-hour means while the model
gives instantaneous values; a wall with a 15 mm plaster layer the model lacks,
calibrated with a discrepancy in the likelihood (its band conditioned on the
training residuals); and a wall whose conductivities rise with temperature
(``helpers/nonlinear_wall.py``), the model's constant, with the same discrepancy.
In the interval-means experiment the parameters the missing physics does not
alias into (k_cb, cp_fb), the wall's thermal resistance, and the bands keep
their rates; the concrete's heat capacity does not: a half-hour mean lags the
instantaneous flux by about 15 minutes, which the model can only reproduce with
more thermal mass, and the flux alone cannot tell the two apart (measured over
10 truths with the white model: cp_cb covered 0 of 10, k_cb and cp_fb 18 of 20,
R_wall 8 of 10, bands 0.954 / 0.957 and 0.504 / 0.517 on train / test; with the
AR(1) model cp_cb 0 of 2). Described as it is (``aggregate = "mean"``: the
calibrated wall averages over each interval too, IntervalMeans), the same
logger's data cover every parameter at its rate.
docs/case-studies.md ("What the intervals promise") states the limit.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pickle
from functools import cache

import pytest
from scipy import stats

from bayescal.emulator.training import train
from coverage import CaseResult, case_data, run_case, trained
from nonlinear_wall import REALISTIC, ConductivityWall
from virtual_wall import NOISE_VARIANCE, plastered_wall

N_TRUTHS = int(os.environ.get("BAYESCAL_VALIDATION_TRUTHS", "2"))
EXPERIMENTS = {
    "white": {"error_model": "white"},
    "ar1": {"error_model": "ar1", "noise_phi": 0.8},
    "white-on-ar1": {"error_model": "white", "noise_phi": 0.8},
    "interval-means": {"error_model": "ar1", "means": True},
    "interval-means-described": {"error_model": "ar1", "means": True, "described": True},
    "white-discrepancy": {"error_model": "white", "discrepancy": True},
    "plaster": {"error_model": "white", "true_wall": plastered_wall(), "discrepancy": True},
    "plaster-both": {"error_model": "white", "true_wall": plastered_wall(), "discrepancy": "both"},
    "conductivity": {
        "error_model": "white",
        "true_wall": ConductivityWall(REALISTIC),
        "discrepancy": True,
    },
}

pytestmark = pytest.mark.slow


@cache
def results(name: str) -> tuple[CaseResult, ...]:
    cases = tuple(run_case(seed, **EXPERIMENTS[name]) for seed in range(N_TRUTHS))  # type: ignore[arg-type]
    report = os.environ.get("BAYESCAL_VALIDATION_REPORT")
    if report:
        with open(report, "a", encoding="utf-8") as f:
            for seed, c in enumerate(cases):
                row = {"experiment": name, "seed": seed, "covered": c.covered}
                row |= {"derived": c.derived_covered, "noise": c.noise_covered}
                row |= {"noise_interval": c.noise_interval}
                row |= {"band95": c.band95, "band50": c.band50, "samples": c.samples}
                row |= {"emulator95": c.emulator95, "emulator50": c.emulator50}
                row |= {"model_error": c.model_error, "model_error_shown": c.model_error_shown}
                row |= {"truth": c.truth}
                f.write(json.dumps(row) + "\n")
    return cases


def test_the_emulator_cache_is_exact() -> None:
    # The experiments of one truth share their simulator runs, so run_case trains their
    # emulator once per process (coverage.trained); the cached one is what training on
    # another experiment's data returns, and other runs train anew.
    _, _, white, _ = case_data(0, **EXPERIMENTS["white"])  # type: ignore[arg-type]
    _, _, ar1, _ = case_data(0, **EXPERIMENTS["ar1"])  # type: ignore[arg-type]
    cached = trained(white, 0)
    assert trained(ar1, 0) is cached
    fresh = train(ar1, n_burn=300, n_draws=100, n_chains=1, seed=0)
    for field in dataclasses.fields(fresh):  # every field, bit for bit
        same = pickle.dumps(getattr(fresh, field.name)) == pickle.dumps(getattr(cached, field.name))
        assert same, field.name
    _, _, described, _ = case_data(0, **EXPERIMENTS["interval-means-described"])  # type: ignore[arg-type]
    assert trained(described, 0) is not cached


def binomial_floor(n: int) -> int:
    """Fewest covering intervals of ``n`` consistent with 95 % (1 % one-sided)."""
    return int(stats.binom.ppf(0.01, n, 0.95))


def _band_bounds(
    level: float, issue: tuple[float, float], n: int, phi: float
) -> tuple[float, float]:
    """Where the mean coverage of ``n`` samples may lie: the issue's range at its size,
    widened to 3.5 binomial standard errors where fewer samples are scored.

    With AR(1) errors neighbouring samples fall inside or outside the band together:
    the binomial uses the effective number ``n (1 - phi) / (1 + phi)``.
    """
    n_eff = n * (1.0 - phi) / (1.0 + phi)
    se = math.sqrt(level * (1.0 - level) / n_eff)
    return min(issue[0], level - 3.5 * se), max(issue[1], level + 3.5 * se)


def _bands_hold(
    cases: tuple[CaseResult, ...],
    phi: float = 0.0,
    route: str = "simulator",
    windows: tuple[str, ...] = ("train", "test"),
) -> None:
    for window in windows:
        n = sum(c.samples[window] for c in cases)
        b95 = [c.band95 if route == "simulator" else c.emulator95 for c in cases]
        b50 = [c.band50 if route == "simulator" else c.emulator50 for c in cases]
        c95 = sum(b[window] * c.samples[window] for b, c in zip(b95, cases, strict=True)) / n
        c50 = sum(b[window] * c.samples[window] for b, c in zip(b50, cases, strict=True)) / n
        lo95, hi95 = _band_bounds(0.95, (0.92, 0.98), n, phi)
        lo50, hi50 = _band_bounds(0.50, (0.45, 0.55), n, phi)
        assert lo95 <= c95 <= hi95, (window, c95, lo95, hi95)
        assert lo50 <= c50 <= hi50, (window, c50, lo50, hi50)


#: The "ar1" experiment is computed once (``results`` is cached per process): the two tests
#: that read it run on one worker under ``make validate``'s ``--dist loadgroup``.
AR1_WORKER = pytest.mark.xdist_group("coverage-ar1")


@pytest.mark.parametrize("name", ["white", pytest.param("ar1", marks=AR1_WORKER)])
def test_intervals_and_bands_cover_at_their_rates(name: str) -> None:
    cases = results(name)
    hits = [ok for c in cases for ok in c.covered.values()]
    assert sum(hits) >= binomial_floor(len(hits)), [c.covered for c in cases]
    # each derived quantity on its own: R and U follow k_cb almost exactly, so pooling
    # them would count one miss three times
    for quantity in cases[0].derived_covered:
        derived = [c.derived_covered[quantity] for c in cases]
        assert sum(derived) >= binomial_floor(len(derived)), (quantity, derived)
    if name == "white":  # the noise SD's interval covers what it estimates
        noise = [c.noise_covered for c in cases]
    else:  # AR(1): an upper estimate of the sensor's noise (method.md section 4a)
        noise = [c.noise_interval[1] >= math.sqrt(NOISE_VARIANCE) for c in cases]
    assert sum(noise) >= binomial_floor(len(noise)), [c.noise_interval for c in cases]
    phi = float(EXPERIMENTS[name].get("noise_phi", 0.0))
    _bands_hold(cases, phi)
    # The emulator's band ([predict] method = "emulator") holds on both windows too.
    _bands_hold(cases, phi, route="emulator")


@AR1_WORKER
def test_the_white_model_fails_on_correlated_noise() -> None:
    hits = [ok for c in results("white-on-ar1") for ok in c.covered.values()]
    assert sum(hits) < binomial_floor(len(hits)), hits
    ar1 = [ok for c in results("ar1") for ok in c.covered.values()]
    assert sum(ar1) > sum(hits)


def test_a_sensor_that_averages_keeps_what_it_does_not_alias() -> None:
    cases = results("interval-means")
    for names in (("k_cb", "cp_fb"), ("R_wall", "U_value")):
        hits = [{**c.covered, **c.derived_covered}[n] for c in cases for n in names]
        assert sum(hits) >= binomial_floor(len(hits)), (names, hits)
    phi = float(EXPERIMENTS["interval-means"].get("noise_phi", 0.0))
    _bands_hold(cases, phi)
    _bands_hold(cases, phi, route="emulator")


def test_a_sensor_described_as_it_averages_keeps_every_rate() -> None:
    # The same averaging logger (here over 12 steps an interval), the calibrated wall now
    # told so (aggregate = "mean": IntervalMeans, 6 steps): no physics is missing (both
    # interpolate the surface temperatures linearly between samples, so what remains is
    # the fine clock's discretisation), and every parameter, the areal heat capacity
    # included, covers at its rate.
    cases = results("interval-means-described")
    hits = [ok for c in cases for ok in c.covered.values()]
    assert sum(hits) >= binomial_floor(len(hits)), [c.covered for c in cases]
    cp_cb = [c.covered["cp_cb"] for c in cases]
    assert sum(cp_cb) >= binomial_floor(len(cp_cb)), cp_cb
    for quantity in cases[0].derived_covered:
        derived = [c.derived_covered[quantity] for c in cases]
        assert sum(derived) >= binomial_floor(len(derived)), (quantity, derived)
    phi = float(EXPERIMENTS["interval-means-described"].get("noise_phi", 0.0))
    _bands_hold(cases, phi)
    _bands_hold(cases, phi, route="emulator")


@pytest.mark.parametrize("name", ["plaster", "plaster-both"])
def test_a_discrepancy_in_the_likelihood_absorbs_a_missing_layer(name: str) -> None:
    # The measuring wall has a 15 mm plaster layer the calibrated model lacks; the
    # white error model with a discrepancy in the likelihood, its band conditioned on
    # the training residuals: over the periods' conditions ("plaster"), or that plus
    # a part independent between periods ("plaster-both"). The parameters and the
    # wall's resistance (U) keep their rates; the areal heat capacity does not (the
    # plaster's mass is not in the model).
    cases = results(name)
    hits = [ok for c in cases for ok in c.covered.values()]
    assert sum(hits) >= binomial_floor(len(hits)), [c.covered for c in cases]
    for quantity in ("R_wall", "U_value"):
        derived = [c.derived_covered[quantity] for c in cases]
        assert sum(derived) >= binomial_floor(len(derived)), (quantity, derived)
    _bands_hold(cases)
    _bands_hold(cases, route="emulator")
    # The areal heat capacity misses the plaster's mass; where its interval does not
    # cover, the first screen says the model misses part of the measurements
    # (calibration.modelerror: the discrepancy's SD above a quarter of the noise SD).
    for c in cases:
        assert c.derived_covered["areal_heat_capacity"] or c.model_error_shown, c.model_error


def test_a_discrepancy_on_a_correct_model_keeps_the_rates_and_raises_no_alarm() -> None:
    # The model is the wall that made the data; the discrepancy is on all the same.
    # The parameters, derived quantities and bands keep their rates, and the data do not
    # show a model error (measured at ten truths: the discrepancy SD's 95 % interval
    # starting at 0.003-0.005 noise SDs, against 2.1-4.2 with the plaster layer missing;
    # no alarm): at most one false alarm in ten.
    cases = results("white-discrepancy")
    hits = [ok for c in cases for ok in c.covered.values()]
    assert sum(hits) >= binomial_floor(len(hits)), [c.covered for c in cases]
    for quantity in cases[0].derived_covered:
        derived = [c.derived_covered[quantity] for c in cases]
        assert sum(derived) >= binomial_floor(len(derived)), (quantity, derived)
    _bands_hold(cases)
    _bands_hold(cases, route="emulator")
    alarms = [c.model_error for c in cases if c.model_error_shown]
    assert len(alarms) <= len(cases) // 10, alarms


def test_a_conductivity_that_rises_with_temperature_is_covered_or_flagged() -> None:
    # Every layer's conductivity rises with temperature by coefficients of the size EN ISO
    # 10456 tabulates (0.5 %/K in the glass-fibre boards, 0.2 %/K in the aerated
    # concrete); the model keeps them constant. At each truth the wall's R (steady, at
    # the training days' mean surface temperatures), U and areal heat capacity are
    # covered, or the first screen says the model misses part of the measurements: at 8
    # of 10 truths or more (issue 35; with fewer truths, a quick check, the binomial
    # floor). Measured at ten: R and U covered 8, the heat capacity 7, the warning shown
    # at 9, so covered or warned 10, 10 and 9.
    cases = results("conductivity")
    need = binomial_floor(len(cases)) if len(cases) < 10 else math.ceil(0.8 * len(cases))
    for quantity in ("R_wall", "U_value", "areal_heat_capacity"):
        ok = [c.derived_covered[quantity] or bool(c.model_error_shown) for c in cases]
        assert sum(ok) >= need, (quantity, [(c.derived_covered, c.model_error) for c in cases])
    _bands_hold(cases)
    _bands_hold(cases, route="emulator")
