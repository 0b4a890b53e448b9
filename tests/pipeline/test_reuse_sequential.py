"""``[design] reuse_screening`` with ``sequential = true``: the screening's runs, then batches.

The virtual wall of :mod:`reuse_study` (two calibrated parameters, two screened-out
candidates whose nominal values are the truth's): a Sobol screening of 12 runs,
then a sequential design whose first design is those 12 runs (from the run cache)
and 4 new ones, with batches of 4 at the current posterior's draws, the
screened-out inputs at their nominal values, up to 24 runs in all. The design is
killed inside its first batch and resumed.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from bayescal.config import load_study
from bayescal.errors import ConfigError
from bayescal.pipeline import Options, run
from bayescal.pipeline.keys import stage_keys
from bayescal.pipeline.reuse import screening_design
from bayescal.pipeline.screen import screen
from bayescal.pipeline.seqdesign import (
    HISTORY_FILE,
    STATE_FILE,
    posterior_shift,
    predict_runs,
)
from bayescal.pipeline.stages import make_design, prepare
from bayescal.runner import sandbox
from reuse_study import EXECUTE, SCREENING_RUNS, SOBOL, Counting, reuse_study
from sequential_study import TRUTH

pytest.importorskip("SALib", reason="Sobol screening needs SALib")

SERIAL = Options(backend="serial", chains_backend="serial")
FIRST_NEW = 4  # the calibrated parameters + 2
CAP = SCREENING_RUNS + FIRST_NEW + 8  # two batches of 4 at most
SEQUENTIAL = f"reuse_screening = true\nsequential = true\nbatch = 4\nmax_runs = {CAP}\n"
NOMINAL = {"k_fb": 0.0316, "d_fb": 116.6}
KILL_AFTER = FIRST_NEW + 2  # the first design's new runs and 2 of the first batch


class _Killed(BaseException):
    """The process killed (not an ``Exception``: nothing on the way catches it)."""


class _Killing(Counting):
    """Counts the simulator runs and kills the process at run ``KILL_AFTER + 1``."""

    def __call__(self, simulator: Any, forcing: Any, parameters: dict[str, float]) -> Any:
        self.calls += 1
        if self.calls > KILL_AFTER:
            raise _Killed
        return EXECUTE(simulator, forcing, parameters)


@pytest.fixture(scope="module")
def grown(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Screen, start the sequential design and kill it in its first batch, resume it, run
    to the predictions, then run again; the simulator runs of each step."""
    folder = reuse_study(tmp_path_factory.mktemp("reuse-seq") / "wall", SEQUENTIAL, runs=4)
    counts: dict[str, int] = {}
    said: list[str] = []
    found: dict[str, Any] = {}
    with pytest.MonkeyPatch.context() as patch:
        counter: Counting = Counting()
        patch.setattr(sandbox, "execute", counter)
        screen(load_study(folder), options=SERIAL)
        counts["screen"] = counter.calls

        counter = _Killing()
        patch.setattr(sandbox, "execute", counter)
        with pytest.raises(_Killed):
            run(load_study(folder), until="design", options=SERIAL)
        counts["killed"] = counter.calls
        out = prepare(load_study(folder)).out
        found["chosen"] = np.asarray(np.load(out / STATE_FILE)["unit"])

        for step, until in (("resume", "design"), ("predict", "predict"), ("again", "predict")):
            counter = Counting()
            patch.setattr(sandbox, "execute", counter)
            found[step] = run(load_study(folder), until=until, options=SERIAL, say=said.append)
            counts[step] = counter.calls
    return {"folder": folder, "out": out, "counts": counts, "said": said, **found}


def test_the_screening_runs_are_not_run_again_and_a_rerun_runs_nothing(
    grown: dict[str, Any],
) -> None:
    counts = grown["counts"]
    design = grown["resume"].design
    assert counts["screen"] == SCREENING_RUNS
    assert counts["killed"] == KILL_AFTER + 1  # the run it was killed in
    assert any("resuming the sequential design at 20 runs" in s for s in grown["said"])
    # resumed: the killed batch's 2 unfinished runs, then every later batch's runs, each
    # once; the screening's runs and every run made before the kill came from the cache
    assert counts["resume"] == 2 + (design.runs - SCREENING_RUNS - FIRST_NEW - 4)
    study = load_study(grown["folder"])
    assert counts["predict"] == study.predict.runs + 1  # the draws and the nominal run only
    assert counts["again"] == 0  # every stage reused
    assert grown["predict"].simulations.n_cached == design.runs


def test_the_design_is_the_screening_then_the_new_runs_then_batches_at_nominal(
    grown: dict[str, Any],
) -> None:
    design = grown["predict"].design
    assert design.names == ("k_cb", "cp_cb", "k_fb", "d_fb")
    assert SCREENING_RUNS + FIRST_NEW + 4 <= design.runs <= CAP
    screening = screening_design(load_study(grown["folder"]))
    np.testing.assert_array_equal(design.values[:SCREENING_RUNS], screening.values)
    # the state saved before the kill is the head of the design, never chosen again
    chosen = grown["chosen"]
    assert len(chosen) == SCREENING_RUNS + FIRST_NEW + 4
    np.testing.assert_array_equal(design.unit[: len(chosen)], chosen)
    new = design.values[SCREENING_RUNS:]
    for k, name in ((2, "k_fb"), (3, "d_fb")):
        np.testing.assert_allclose(new[:, k], NOMINAL[name], rtol=1e-12)
    assert np.ptp(screening.values[:, 2]) > 0.0  # the screening did vary them
    # the batches are at the posterior's draws: closer together than the prior box
    batches = design.values[SCREENING_RUNS + FIRST_NEW :]
    width = 0.16 - 0.08
    assert np.ptp(batches[:, 0]) < 0.5 * width
    assert np.ptp(design.values[SCREENING_RUNS : SCREENING_RUNS + FIRST_NEW, 0]) > 0.5 * width
    history = pd.read_csv(grown["out"] / HISTORY_FILE)
    assert history["runs"].tolist() == sorted(set(history["runs"]))  # no step twice
    assert history["runs"].iloc[0] == SCREENING_RUNS + FIRST_NEW
    assert history["runs"].iloc[-1] == design.runs
    assert any(
        f"the {SCREENING_RUNS} runs of the Sobol screening, then {design.runs - SCREENING_RUNS}"
        in s
        for s in grown["said"]
    )


def test_the_posterior_holds_them_at_nominal_and_covers_the_truth(
    grown: dict[str, Any],
) -> None:
    post = grown["predict"].posterior
    assert post.names == ("k_cb", "cp_cb", "k_fb", "d_fb")
    assert post.held_names == ("k_fb", "d_fb")
    draws = post.draws.reshape(-1, 4)
    np.testing.assert_allclose(draws[:, 2], NOMINAL["k_fb"], rtol=1e-12)
    np.testing.assert_allclose(draws[:, 3], NOMINAL["d_fb"], rtol=1e-12)
    for k, name in enumerate(("k_cb", "cp_cb")):
        lower, upper = np.quantile(draws[:, k], [0.025, 0.975])
        assert lower <= TRUTH[name] <= upper, (name, lower, upper)
    assert np.ptp(np.quantile(draws[:, 0], [0.025, 0.975])) < 0.2 * (0.16 - 0.08)


def test_runs_zero_makes_the_screening_alone_the_first_design(
    grown: dict[str, Any], tmp_path: Path
) -> None:
    folder = tmp_path / "wall"
    shutil.copytree(grown["folder"], folder)
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8").replace("[design]\nruns = 4\n", "[design]\nruns = 0\n")
    path.write_text(text, encoding="utf-8")
    study = load_study(folder)
    first = make_design(prepare(study))
    assert first.runs == SCREENING_RUNS
    np.testing.assert_array_equal(first.values, screening_design(study).values)


def _load(tmp_path: Path, design: str, runs: int = 4) -> Any:
    return load_study(reuse_study(tmp_path / "wall", design, runs=runs))


def test_reuse_with_sequential_loads_and_counts_the_screening_in_max_runs(
    tmp_path: Path,
) -> None:
    study = _load(tmp_path, "reuse_screening = true\nsequential = true\n")
    # the default: the screening's runs + three times runs
    assert study.design.run_cap(SCREENING_RUNS) == SCREENING_RUNS + 3 * 4
    alone = _load(tmp_path / "a", "reuse_screening = true\nsequential = true\nmax_runs = 20\n", 0)
    assert alone.design.runs == 0
    # the screening's 12 runs count towards the first design's parameters + 2: one new run
    # is enough for a one-shot design
    assert _load(tmp_path / "b", "reuse_screening = true\n", 1).design.runs == 1


@pytest.mark.parametrize(
    ("design", "runs", "match"),
    [
        ("reuse_screening = true\nsequential = true\nmax_runs = 15\n", 4,
         r"design\.max_runs: 15 is below the first design's 16 runs \(the screening's 12 \+ "
         r"design\.runs 4\): with reuse_screening it counts the screening's runs too"),
        ("reuse_screening = true\nsequential = true\n", 0,
         r"design\.max_runs: 12 leaves no batch after the first design's 12 runs"),
        ("reuse_screening = true\n", 0,
         r"design\.runs: 0 new runs after the screening's 12 for 2 calibrated parameters; at "
         r"least 1 is needed \(or 0 with sequential = true\)"),
        ("sequential = true\n", 0, r"design\.runs: 0 runs for 2 calibrated parameters; at "
         r"least 4 are needed(?! \(or 0)"),
    ],
)  # fmt: skip
def test_impossible_runs_and_caps_are_one_line(
    tmp_path: Path, design: str, runs: int, match: str
) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        _load(tmp_path, design, runs)
    assert "\n" not in str(info.value)


def test_the_design_key_follows_the_screening_and_the_sequential_settings(
    tmp_path: Path,
) -> None:
    def key(name: str, design: str, screening: str = SOBOL) -> str:
        folder = reuse_study(tmp_path / name, design, screening, runs=4)
        return stage_keys(prepare(load_study(folder)))["design"]

    one_shot = key("a", "reuse_screening = true\n")
    sequential = key("b", "reuse_screening = true\nsequential = true\n")
    reseeded = key("c", "reuse_screening = true\nsequential = true\n", SOBOL + "seed = 3\n")
    plain = key("d", "sequential = true\n")
    assert len({one_shot, sequential, reseeded, plain}) == 4


def test_the_steps_leave_the_held_inputs_out_of_the_shift_and_the_line(
    grown: dict[str, Any],
) -> None:
    """The held inputs' posterior SD is rounding (~1e-16): neither printed with the
    posterior nor differentiated in the stopping rule's shift."""
    steps = [s for s in grown["said"] if s.startswith("design: ") and "; posterior " in s]
    assert steps
    for line in steps:
        tail = line.split("; posterior ", 1)[1]
        assert "k_cb" in tail
        assert "cp_cb" in tail
        assert "k_fb" not in tail
        assert "d_fb" not in tail
    em = grown["predict"].emulator
    names = em.emulator.parameter_names
    mean = {n: float(v) for n, v in zip(names, grown["predict"].design.values[-1], strict=True)}
    noise = {o: 1.0 for o in em.emulator.outputs.names}
    diffs = 0.01 * np.random.default_rng(0).normal(size=predict_runs(em, mean_row(mean)).shape)
    rounding = {n: (1e-3 * abs(mean[n]) if n in ("k_cb", "cp_cb") else 1e-16) for n in names}
    exact = {n: (rounding[n] if n in ("k_cb", "cp_cb") else 0.0) for n in names}
    assert posterior_shift(em, diffs, noise, mean, rounding) == pytest.approx(
        posterior_shift(em, diffs, noise, mean, exact), rel=1e-12
    )


def mean_row(mean: dict[str, float]) -> np.ndarray:
    return np.array([list(mean.values())])
