"""``[predict] method = "auto"``: the route chosen by the emulator's error at held-out runs.

The tiny virtual-wall study of ``test_seqdesign`` (8 design runs, two basis
vectors): its emulator's weights miss the held-out runs' part on the basis by
about 0.1 noise SD on the test window (measured), so a tolerance below that takes
the simulator route, and one above it (the default 0.3 included) the emulator
route, making only the held-out runs. Compared with the whole runs, off-basis
part included, the emulator route's centre misses them by about 1 noise SD: the
band holds that part apart, and the run warns that the route's point metrics
are worse than the simulator route's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_seqdesign import _study

from bayescal.cli.progress import describe
from bayescal.config import load_study
from bayescal.pipeline import Options, Results, load_results, run
from bayescal.pipeline.predict import thin_draws
from bayescal.pipeline.route import check_draws
from bayescal.pipeline.stages import prepare

RUNS, CHECK = 10, 3  # fewer held-out runs than the emulator would need (t + 2 = 4)
TIGHT = 0.02  # below the emulator's measured error here (about 0.1 noise SD)


def _auto(folder: Path, tolerance: float) -> tuple[list[str], Results, int]:
    _study(folder, "[design]\nruns = 8\n")
    text = (folder / "study.toml").read_text(encoding="utf-8")
    text += (
        f'\n[predict]\nmethod = "auto"\nruns = {RUNS}\ncheck_runs = {CHECK}\n'
        f"check_tolerance = {tolerance}\n"
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


def test_a_tolerance_above_the_measured_error_takes_the_emulator_route(
    simulator_route: tuple[list[str], Results, int], tmp_path: Path
) -> None:
    (first,) = [s for s in simulator_route[0] if "method = 'auto' chose" in s]
    measured = float(first.split("heat_flux_in ")[1].split(" x")[0])
    said, res, cached = _auto(tmp_path / "wall", max(2 * measured, 0.3))
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
