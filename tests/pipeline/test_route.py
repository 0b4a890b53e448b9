"""``[predict] method = "auto"``: the route chosen by the emulator's error at held-out runs.

The tiny virtual-wall study of ``test_seqdesign`` (8 design runs, two basis
vectors): its emulator's weights miss the held-out runs' part on the basis by
about 0.1 noise SD on the test window (measured), so a tolerance below that takes
the simulator route, and one above it (the default 0.3 included) the emulator
route, making only the held-out runs. Compared with the whole runs, off-basis
part included, the emulator's centre misses them by about 1.4 noise SD: left on
the basis (``[predict] off_basis = "none"``) the band holds that part apart, and
the run warns that the route's point metrics are worse than the simulator
route's; completed with the held-out runs' mean part (the default) it misses each
run, against the other runs' part, by less than the tolerance, and its test-window
RMSE is the simulator route's (measured 0.1013 against 0.1011 W/m²; on the basis
0.2026).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_seqdesign import _study

from bayescal.cli.progress import describe
from bayescal.config import load_study
from bayescal.config.predict import PredictSection
from bayescal.pipeline import Options, Results, load_results, run
from bayescal.pipeline.completed import completed_band
from bayescal.pipeline.predict import predict_band, thin_draws, windows
from bayescal.pipeline.route import RouteCheck, check_draws
from bayescal.pipeline.stages import prepare

RUNS, CHECK = 10, 3  # fewer held-out runs than the emulator would need (t + 2 = 4)
TIGHT = 0.02  # below the emulator's measured error here (about 0.1 noise SD)


def _auto(folder: Path, tolerance: float, extra: str = "") -> tuple[list[str], Results, int]:
    _study(folder, "[design]\nruns = 8\n")
    text = (folder / "study.toml").read_text(encoding="utf-8")
    text += (
        f'\n[predict]\nmethod = "auto"\nruns = {RUNS}\ncheck_runs = {CHECK}\n'
        f"check_tolerance = {tolerance}\n{extra}"
    )
    (folder / "study.toml").write_text(text, encoding="utf-8")
    said: list[str] = []
    study = load_study(folder)
    res = run(study, until="predict", options=Options(backend="serial"), say=said.append)
    cached = len(list((prepare(study).out / "simulations" / "runs").glob("*.npz")))
    return said, res, cached


@pytest.fixture(scope="module")
def simulator_route(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[str], Results, int]:
    return _auto(tmp_path_factory.mktemp("route") / "wall", TIGHT)


def test_an_error_above_the_tolerance_takes_the_simulator_route_reusing_the_held_out_runs(
    simulator_route: tuple[list[str], Results, int],
) -> None:
    said, res, cached = simulator_route
    (line,) = [s for s in said if "method = 'auto' chose" in s]
    assert "chose the simulator route" in line
    ratio = float(line.split("heat_flux_in ")[1].split(" x")[0])
    assert ratio > TIGHT
    assert res.predictions is not None
    assert res.predictions.dataset.attrs["route"] == "simulator"
    assert cached == 8 + 1 + RUNS  # design, nominal, the route's runs (the check's among them)
    assert not [s for s in said if "off the output basis" in s]  # the simulator's centre


def _measured(said: list[str]) -> float:
    (line,) = [s for s in said if "method = 'auto' chose" in s]
    return float(line.split("heat_flux_in ")[1].split(" x")[0])


def _test_rmse(res: Results) -> float:
    assert res.predictions is not None
    m = res.predictions.metrics
    row = m[(m.model == "calibrated") & (m.window == "test")]
    return float(row.rmse.iloc[0])


def test_the_emulator_routes_centre_left_on_the_basis_is_said(
    simulator_route: tuple[list[str], Results, int], tmp_path: Path
) -> None:
    measured = _measured(simulator_route[0])
    said, res, cached = _auto(tmp_path / "wall", max(2 * measured, 0.3), 'off_basis = "none"\n')
    (line,) = [s for s in said if "method = 'auto' chose" in s]
    assert "chose the emulator route" in line
    assert res.predictions is not None
    assert res.predictions.dataset.attrs["route"] == "emulator"
    assert cached == 8 + 1 + CHECK  # only the held-out runs were made
    # its centre leaves out the runs' part off the basis (about 1 noise SD here): said
    (warning,) = [s for s in said if "leaves out the runs' part off the output basis" in s]
    assert warning.startswith("WARNING: ")
    centre = float(warning.split("heat_flux_in ")[1].split(" x")[0])
    assert centre > max(2 * measured, 0.3) > measured
    # kept with the predictions: `show` repeats it on its first screen
    shown = describe(load_results(load_study(tmp_path / "wall")))
    assert warning in shown.split("posterior (physical units):")[0]
    run(load_study(tmp_path / "wall"), options=Options(backend="serial"))  # the report
    html = (prepare(load_study(tmp_path / "wall")).out / "report" / "report.html").read_text(
        encoding="utf-8"
    )
    assert "leaves out the runs&#x27; part off the output basis" in html or (
        "leaves out the runs' part off the output basis" in html
    )
    assert "its centre completed off the output basis" not in html
    # twice the simulator route's RMSE on the test window (measured 0.203 / 0.101)
    assert _test_rmse(res) > 1.5 * _test_rmse(simulator_route[1])


def test_the_emulator_routes_centre_completed_off_the_basis_is_the_simulators(
    simulator_route: tuple[list[str], Results, int], tmp_path: Path
) -> None:
    """The default: the held-out runs' mean part off the basis completes the centre."""
    measured = _measured(simulator_route[0])
    tolerance = max(2 * measured, 0.3)
    said, res, cached = _auto(tmp_path / "wall", tolerance)
    (line,) = [s for s in said if "method = 'auto' chose" in s]
    assert "chose the emulator route" in line
    assert "its centre is completed with those runs' mean part off the output basis" in line
    completed = float(line.split("held out: heat_flux_in ")[1].split(" x")[0])
    assert completed <= tolerance  # each run against the others' part: no warning
    assert not [s for s in said if "off the output basis" in s and s.startswith("WARNING")]
    assert cached == 8 + 1 + CHECK  # no run beyond the held-out ones
    assert res.predictions is not None
    assert res.predictions.dataset.attrs["off_basis"]
    # the simulator route's RMSE on the test window (the same posterior), within 5 %
    assert _test_rmse(res) == pytest.approx(_test_rmse(simulator_route[1]), rel=0.05)
    run(load_study(tmp_path / "wall"), options=Options(backend="serial"))  # the report
    html = (prepare(load_study(tmp_path / "wall")).out / "report" / "report.html").read_text(
        encoding="utf-8"
    )
    assert "its centre completed off the output basis by the held-out runs" in html
    # `show` and the report repeat what the check measured
    shown = describe(load_results(load_study(tmp_path / "wall")))
    assert (
        "bands from the emulator at posterior draws, its centre completed off the output "
        "basis by the held-out runs (method = 'auto' chose the emulator route" in shown
    )
    assert f"held out: heat_flux_in {completed:.2f} x the noise SD" in shown
    assert "method = &#x27;auto&#x27; chose the emulator route" in html or (
        "method = 'auto' chose the emulator route" in html
    )


def test_the_held_out_draws_are_among_the_simulator_routes_draws(
    simulator_route: tuple[list[str], Results, int],
) -> None:
    post = simulator_route[1].posterior
    assert post is not None
    _, _, route = thin_draws(post, RUNS)
    _, _, every = thin_draws(post, 10**9)
    sub = check_draws(RUNS, CHECK, len(route))
    assert len(sub) == CHECK
    assert set(route[sub]) <= set(route) <= set(every)
    assert np.all(np.diff(sub) > 0)


def test_the_completed_band_with_no_part_off_the_basis_is_the_emulator_routes(
    simulator_route: tuple[list[str], Results, int],
) -> None:
    """With a zero part off the basis and the calibration's noise the completed band is
    the emulator route's on the training periods (1e-10; the test window adds the runs'
    out-of-basis excess there only), and a constant part moves its centre by that part."""
    res = simulator_route[1]
    assert res.emulator is not None
    assert res.posterior is not None
    em, post = res.emulator, res.posterior
    layout = em.assembled.layout
    zero = {
        o: (np.zeros(layout.n_total), np.zeros(layout.n_total)) for o in em.emulator.outputs.slices
    }
    kwargs = {"draws": 40, "level": 0.95}
    done = completed_band(em.emulator, em.assembled, post, zero, noise="calibration", **kwargs)
    plain = predict_band(em.emulator, em.assembled, post, **kwargs)
    train = windows(layout) == "train"
    for name in em.emulator.outputs.slices:
        for a, b in [
            (done.mean, plain.mean),
            (done.lower, plain.lower),
            (done.upper50, plain.upper50),
        ]:
            np.testing.assert_allclose(a[name][train], b[name][train], rtol=1e-10, atol=1e-12)
    shifted = {o: (np.full(layout.n_total, 0.25), np.zeros(layout.n_total)) for o in zero}
    moved = completed_band(em.emulator, em.assembled, post, shifted, noise="calibration", **kwargs)
    for name in em.emulator.outputs.slices:
        finite = np.isfinite(done.mean[name])
        np.testing.assert_allclose(
            moved.mean[name][finite], done.mean[name][finite] + 0.25, rtol=1e-10
        )
    with pytest.raises(ValueError, match="no part off the basis"):
        completed_band(em.emulator, em.assembled, post, {}, **kwargs)


def test_the_completion_needs_two_held_out_runs() -> None:
    """``off_basis = "check_runs"`` under ``auto`` with one held-out run is refused in one
    line that says how to fix it; ``"none"`` or another method accepts one."""
    with pytest.raises(ValueError, match=r"needs at least two of them \(check_runs = 1\): raise"):
        PredictSection(method="auto", check_runs=1)
    assert PredictSection(method="auto", check_runs=1, off_basis="none").check_runs == 1
    assert PredictSection(method="simulator", check_runs=1).off_basis == "check_runs"


def test_a_completion_skipped_for_failed_runs_is_said() -> None:
    check = RouteCheck("emulator", {"q": 0.1}, 1, "test", 0.3, {"q": 0.9}, skipped=True)
    assert not check.completes
    assert "NOT completed off the output basis: fewer than two held-out runs" in check.line()
    warning = check.warning()
    assert warning is not None
    assert "raise [predict] check_runs" in warning
    assert "set [predict] off_basis" not in warning


def test_a_completed_centre_that_still_misses_is_said() -> None:
    """The warning follows the completed centre's held-out error where the centre is
    completed, and names what to raise; within the tolerance it is silent."""
    part = {"q": (np.zeros(4), np.zeros(4))}
    check = RouteCheck("emulator", {"q": 0.1}, 5, "test", 0.3, {"q": 1.2}, {"q": 0.5}, part)
    assert check.completes
    warning = check.warning()
    assert warning is not None
    assert "completed with the held-out runs' mean part off the output basis, still" in warning
    assert "q 0.50 x the noise SD" in warning
    assert "raise [predict] check_runs" in warning
    quiet = RouteCheck("emulator", {"q": 0.1}, 5, "test", 0.3, {"q": 1.2}, {"q": 0.2}, part)
    assert quiet.warning() is None  # the centre left on the basis (1.2) is not the band's
    simulator = RouteCheck("simulator", {"q": 0.4}, 5, "test", 0.3, {"q": 1.2}, {"q": 0.5}, part)
    assert simulator.warning() is None
