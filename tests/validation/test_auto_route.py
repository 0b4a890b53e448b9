"""``[predict] method = "auto"`` at known truths: the route it picks and its bands' rates.

Each truth (k_cb and cp_cb drawn as ``virtual_wall.random_truth`` draws them,
inside the middle 80 % of the paper's priors; the boards keep 840 J/(kg·K)) gets
a virtual-wall study: :data:`compare_study.STUDY` with 1 warm-up day, 6 training
days and a 2-day test window of white noise (SD sqrt(0.007) W/m²,
``compare_study.wall_data``), 20 design runs, 2 basis vectors, chains
4 x (500 + 1000), the white error model and ``[predict] method = "auto"``
(``runs`` 50, ``check_runs`` 5). ``bayescal.pipeline.run`` takes it up to
predict twice: at the default ``check_tolerance`` (0.3) and at a tight 0.01
(only the predict stage runs again: the tolerance is in its key alone), and once
more at the default with ``off_basis = "none"``. The tests check

* the route is recorded in the predictions (``attrs["route"]``, one of the two),
  named by the line ``auto`` prints with its measured ratio (the emulator's RMS
  error at the held-out runs, against their part on the output basis, over the
  noise SD), and follows the ratio: the emulator route exactly where the ratio is
  at most the tolerance; the ratio is the same at both tolerances, the default
  takes the emulator route at all truths but one or more (this wall's emulator is
  accurate) and the tight one the simulator route at every truth;
* at each tolerance, pooled over the truths, the calibrated 95 % band covers the
  measured samples of the test window (and of the training periods) within
  0.92-0.98 and the 50 % band within 0.45-0.55, widened to 3.5 binomial
  standard errors of the pooled number of samples where fewer are scored (the
  noise is white: the samples are close to independent given the posterior;
  2 truths, 192 test samples: 0.895-1.0 and 0.374-0.626);
* the parameters' 95 % intervals cover the truths at least as often as the 1 %
  quantile of Binomial(n, 0.95) (16 of 20 at 10 truths, 2 of 4 at 2);
* the emulator route's centre, completed with the held-out runs' part off the
  output basis (``[predict] off_basis = "check_runs"``, the default), predicts as
  well as the simulator route (pooled RMSE within 5 %), and left on the basis
  (``"none"``, a third pass) at least 1.2 times worse.

Measured over 10 truths (``BAYESCAL_VALIDATION_TRUTHS=10``, 960 test and 2880
training samples pooled). At the default tolerance, with the centre completed (its
ratios over the noise the completed band uses, estimated again from the held-out
runs: 0.03-0.38), the emulator route at 9 of 10 truths (truth 0, 0.38, the
simulator route); 95 % band 0.955 test / 0.958 train, 50 % band 0.521 / 0.494,
pooled RMSE 0.0830 / 0.0828 W/m² against the simulator route's 0.0826 / 0.0826 at
every truth (95 % 0.954 / 0.957, 50 % 0.522 / 0.496). Left on the basis (ratios
over the calibration's noise, 0.02-0.26: the emulator route at all 10) 0.154 /
0.117 W/m², 95 % 0.973 / 0.952, 50 % 0.507 / 0.504. 20 of 20 parameter intervals
cover their truths. About 4 minutes in all on the loaded 2-core machine. Before
the check compared with the runs' part on the basis it read 0.85-1.56 here (the
runs' out-of-basis part, which the emulator route's band holds apart) and sent
every truth to the simulator route: the tight pass keeps that route under test.
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from bayescal.config import load_study
from bayescal.pipeline import Options, Results, run
from compare_study import wall_data
from virtual_wall import random_truth

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

import predict_truths

N_TRUTHS = int(os.environ.get("BAYESCAL_VALIDATION_TRUTHS", "2"))
SEED = 20261205
#: The record's noise seed of truth ``i`` is ``DATA_SEED + i``, the study's seed ``11 + i``.
DATA_SEED = 3000
CALIBRATED = ("k_cb", "cp_cb")
TRAIN_DAYS, TEST_DAYS = 6, 2
ROUTES = ("emulator", "simulator")
#: ``check_tolerance`` of the runs of every study: the default, one below the error the
#: check measures on this wall (so that "auto" takes the simulator route), and the
#: default with the emulator route's centre left on the output basis
#: (``[predict] off_basis = "none"``).
TOLERANCES = {"default": None, "tight": 0.01, "basis": None}

#: One worker runs every test of this file (they share its module fixtures): `make
#: validate` spreads the tests over workers by `--dist loadgroup`.
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("auto-route")]


@dataclass(frozen=True)
class Predicted:
    """The predict stage of one study with ``method = "auto"`` at one tolerance."""

    route: str  # the route recorded in the predictions (attrs["route"])
    said: str  # the line that names the chosen route
    ratio: float  # the emulator's RMS error at the held-out runs / the noise SD
    tolerance: float
    inside95: dict[str, int]  # window -> measured samples inside the 95 % band
    inside50: dict[str, int]
    samples: dict[str, int]  # window -> measured samples scored
    rmse: dict[str, float]  # window -> RMSE of the calibrated prediction's centre
    seconds: float  # the whole pipeline (default) or the predict stage alone (tight)


@dataclass(frozen=True)
class Case:
    """One truth: its parameters' coverage and the predictions at each tolerance."""

    truth: dict[str, float]
    covered: dict[str, bool]  # parameter -> its 95 % interval holds the truth
    predicted: dict[str, Predicted]  # TOLERANCES key -> the predict stage


def study_text(name: str, seed: int, tolerance: float | None, basis: bool = False) -> str:
    """The study of ``scripts/predict_truths.py`` (:data:`compare_study.STUDY` at this
    check's size) with ``method = "auto"`` added to its last table, ``[predict]``
    (``basis``: the emulator route's centre left on the output basis)."""
    text = predict_truths.study_text(name, seed, False, test_days=TEST_DAYS)
    if not text.rstrip().split("\n[")[-1].startswith("predict]"):
        raise RuntimeError("predict_truths.study_text no longer ends with [predict]")
    text += 'method = "auto"\n' + ('off_basis = "none"\n' if basis else "")
    return text + ("" if tolerance is None else f"check_tolerance = {tolerance}\n")


def predict(
    folder: Path, index: int, tolerance: float | None, basis: bool = False
) -> tuple[Predicted, Results]:
    """(Re)write the study at ``tolerance`` and run it up to predict (stages before
    predict are reused when they ran already: the tolerance is in the predict key only)."""
    (folder / "study.toml").write_text(
        study_text(folder.name, 11 + index, tolerance, basis), encoding="utf-8"
    )
    said: list[str] = []
    start = time.perf_counter()
    study = load_study(folder)
    res = run(study, until="predict", options=Options(backend="serial"), say=said.append)
    seconds = time.perf_counter() - start
    assert res.predictions is not None
    (line,) = [s for s in said if "method = 'auto' chose" in s]
    ratio = float(line.split("heat_flux_in ")[1].split(" x")[0])
    ds = res.predictions.dataset
    y = ds["heat_flux_in_measured"].values
    inside95, inside50, samples, rmse = {}, {}, {}, {}
    for window in ("train", "test"):
        mask = (ds["window"].values == window) & np.isfinite(y)
        band = {e: ds[f"heat_flux_in_calibrated_{e}"].values[mask] for e in ("lower", "upper")}
        band |= {e: ds[f"heat_flux_in_calibrated_{e}"].values[mask] for e in ("lower50", "upper50")}
        inside95[window] = int(np.sum((y[mask] >= band["lower"]) & (y[mask] <= band["upper"])))
        inside50[window] = int(np.sum((y[mask] >= band["lower50"]) & (y[mask] <= band["upper50"])))
        samples[window] = int(mask.sum())
        centre = ds["heat_flux_in_calibrated"].values[mask]
        rmse[window] = float(np.sqrt(np.mean((centre - y[mask]) ** 2)))
    out = Predicted(
        str(ds.attrs["route"]),
        line,
        ratio,
        study.predict.check_tolerance,
        inside95,
        inside50,
        samples,
        rmse,
        seconds,
    )
    return out, res


def one_truth(index: int, truth: dict[str, float], folder: Path) -> Case:
    """Write the study of truth ``index``, run it up to predict at both tolerances."""
    folder.mkdir(parents=True)
    data = wall_data(
        seed=DATA_SEED + index, days=TRAIN_DAYS, phi=0.0, truth=truth, test_days=TEST_DAYS
    )
    data.to_csv(folder / "wall.csv", index=False)
    predicted, results = {}, {}
    for key, tolerance in TOLERANCES.items():  # the default first: it runs every stage
        predicted[key], results[key] = predict(folder, index, tolerance, key == "basis")
    post = results["default"].posterior
    again = results["tight"].posterior
    assert post is not None
    assert again is not None
    assert np.array_equal(post.draws, again.draws)  # the tight run reused the posterior
    lower, upper = post.interval(0.95)
    covered = {
        n: bool(lo <= truth[n] <= hi) for n, lo, hi in zip(post.names, lower, upper, strict=True)
    }
    return Case(truth, covered, predicted)


def truths(n: int) -> list[dict[str, float]]:
    """``n`` truths of k_cb and cp_cb inside the middle 80 % of the priors (boards 840)."""
    rng = np.random.default_rng(SEED)
    return [{k: v for k, v in random_truth(rng).items() if k in CALIBRATED} for _ in range(n)]


@pytest.fixture(scope="module")
def cases(tmp_path_factory: pytest.TempPathFactory) -> tuple[Case, ...]:
    root = tmp_path_factory.mktemp("auto")
    out = tuple(one_truth(i, t, root / f"wall-{i}") for i, t in enumerate(truths(N_TRUTHS)))
    for i, c in enumerate(out):
        for key, p in c.predicted.items():
            print(
                f"truth {i} {key}: {p.route} (ratio {p.ratio:.2f}), 95 % test "
                f"{p.inside95['test']}/{p.samples['test']} train "
                f"{p.inside95['train']}/{p.samples['train']}, 50 % test "
                f"{p.inside50['test']}/{p.samples['test']} train "
                f"{p.inside50['train']}/{p.samples['train']}, RMSE test "
                f"{p.rmse['test']:.4f} train {p.rmse['train']:.4f}, covered {c.covered}, "
                f"{p.seconds:.1f} s"
            )
    for key in TOLERANCES:
        runs = [c.predicted[key] for c in out]
        rates = {w: pooled(runs, w) for w in ("test", "train")}
        print(f"{key}: pooled (95 %, 50 %, samples) {rates}, routes {[p.route for p in runs]}")
    return out


def pooled(runs: list[Predicted], window: str) -> tuple[float, float, int]:
    """The 95 % and 50 % bands' coverage of ``window``'s samples pooled over ``runs``,
    and the number of samples."""
    n = sum(p.samples[window] for p in runs)
    c95 = sum(p.inside95[window] for p in runs) / n
    c50 = sum(p.inside50[window] for p in runs) / n
    return c95, c50, n


def binomial_floor(n: int) -> int:
    """Fewest covering intervals of ``n`` consistent with 95 % (1 % one-sided)."""
    return int(stats.binom.ppf(0.01, n, 0.95))


def band_bounds(level: float, issue: tuple[float, float], n: int) -> tuple[float, float]:
    """Where the pooled coverage of ``n`` independent samples may lie: the issue's range,
    widened to 3.5 binomial standard errors where fewer samples are scored."""
    se = math.sqrt(level * (1.0 - level) / n)
    return min(issue[0], level - 3.5 * se), max(issue[1], level + 3.5 * se)


@pytest.mark.parametrize("key", list(TOLERANCES))
def test_auto_records_its_route_and_its_bands_hold(cases: tuple[Case, ...], key: str) -> None:
    runs = [c.predicted[key] for c in cases]
    for p in runs:
        assert p.route in ROUTES, p.route
        assert f"chose the {p.route} route" in p.said, p.said
        assert (p.route == "emulator") == (p.ratio <= p.tolerance), p.said
    for window in ("test", "train"):
        c95, c50, n = pooled(runs, window)
        lo95, hi95 = band_bounds(0.95, (0.92, 0.98), n)
        lo50, hi50 = band_bounds(0.50, (0.45, 0.55), n)
        assert lo95 <= c95 <= hi95, (window, c95, lo95, hi95)
        assert lo50 <= c50 <= hi50, (window, c50, lo50, hi50)


def test_the_route_follows_the_measured_error(cases: tuple[Case, ...]) -> None:
    default = [c.predicted["default"] for c in cases]
    tight = [c.predicted["tight"] for c in cases]
    # the same posterior and held-out runs: the same measured error at both tolerances
    assert [p.ratio for p in default] == [p.ratio for p in tight]
    # the emulator of this wall is accurate: the default takes its route at most truths
    assert sum(p.route == "emulator" for p in default) >= len(default) - 1, [
        p.said for p in default
    ]
    assert all(p.route == "simulator" for p in tight), [p.said for p in tight]


def test_the_completed_centre_is_the_simulator_routes(cases: tuple[Case, ...]) -> None:
    """The emulator route's centre completed with the held-out runs' part off the basis
    (the default) predicts the measurements as well as the simulator re-run at the
    draws (pooled RMSE within 5 %); left on the basis it is worse by more than that
    part (measured at 10 truths: module docstring)."""
    for window in ("test", "train"):
        mse = {
            key: np.mean([c.predicted[key].rmse[window] ** 2 for c in cases]) for key in TOLERANCES
        }
        rmse = {key: float(np.sqrt(v)) for key, v in mse.items()}
        emulated = [c for c in cases if c.predicted["default"].route == "emulator"]
        assert emulated, "no truth took the emulator route"
        assert rmse["default"] <= 1.05 * rmse["tight"], (window, rmse)
        assert rmse["basis"] >= 1.2 * rmse["default"], (window, rmse)


def test_the_parameters_intervals_cover_the_truths(cases: tuple[Case, ...]) -> None:
    hits = [ok for c in cases for ok in c.covered.values()]
    assert sum(hits) >= binomial_floor(len(hits)), [c.covered for c in cases]
