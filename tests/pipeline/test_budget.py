"""The memory and disk a study's sizes imply, refused before anything is allocated."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayescal.config import load_study
from bayescal.data import load_measured
from bayescal.errors import ConfigError
from bayescal.examples import copy_example
from bayescal.pipeline import Options, run
from bayescal.pipeline.budget import (
    DISK_VARIABLE,
    MEMORY_VARIABLE,
    check_budget,
    estimate,
    estimate_time,
    format_bytes,
    format_seconds,
    machine_memory,
)


def _wall(tmp_path: Path, *edits: tuple[str, str]) -> Path:
    folder = copy_example("wall", tmp_path / "wall")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    path.write_text(text, encoding="utf-8")
    return folder


def test_the_estimate_counts_the_arrays_the_study_makes(tmp_path: Path) -> None:
    study = load_study(_wall(tmp_path))
    measured = load_measured(study)
    needs = {need.what: need for need in estimate(study, measured)}
    # the stacked simulations: runs x samples x outputs float64, twice (cache and stack)
    assert needs["simulations"].memory == 2 * 30 * measured.n * 1 * 8
    assert needs["design"].memory == 2 * 30 * 3 * 8
    assert needs["simulations"].key == "design.runs"
    total = sum(need.memory for need in needs.values())
    assert total < 100 * 2**20  # the shipped example is small
    assert format_bytes(22.4 * 2**30) == "22.4 GiB"
    assert format_bytes(512) == "512 B"


def test_a_billion_runs_are_refused_before_the_output_folder_exists(tmp_path: Path) -> None:
    folder = _wall(tmp_path, ("runs = 30", "runs = 1000000000"))
    study = load_study(folder)
    with pytest.raises(ConfigError, match=r"design\.runs = 1000000000: .* of memory") as info:
        run(study, options=Options(backend="serial"))
    assert "\n" not in str(info.value)
    assert not (folder / "out").exists()


def test_the_limit_is_the_studys_then_the_environments_then_the_machines(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = _wall(tmp_path, ("runs = 30", "runs = 3000"))
    study = load_study(folder)
    measured = load_measured(study)
    need = sum(n.memory for n in estimate(study, measured))
    assert need > 2**30  # the run correlations alone: basis x 3000²
    monkeypatch.setenv(MEMORY_VARIABLE, "100MiB")
    with pytest.raises(ConfigError, match=rf"more than the 100 MiB of {MEMORY_VARIABLE}"):
        check_budget(study, measured)
    monkeypatch.setenv(MEMORY_VARIABLE, "1TiB")
    check_budget(study, measured)  # a big machine says so
    monkeypatch.setenv(MEMORY_VARIABLE, "a lot")
    with pytest.raises(ConfigError, match=rf"{MEMORY_VARIABLE}='a lot' is not a size"):
        check_budget(study, measured)
    monkeypatch.delenv(MEMORY_VARIABLE)
    runner = 'runs = 50\n\n[runner]\nmax_memory = "100MiB"'
    limited = load_study(_wall(tmp_path / "b", ("runs = 30", "runs = 3000"), ("runs = 50", runner)))
    monkeypatch.setenv(MEMORY_VARIABLE, "1TiB")  # the study's own setting wins
    with pytest.raises(ConfigError, match=r"more than the 100 MiB of \[runner\] max_memory"):
        check_budget(limited, measured)
    assert machine_memory() is None or machine_memory() > 2**20


def test_disk_is_checked_against_the_free_space_of_the_output_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    study = load_study(_wall(tmp_path))
    measured = load_measured(study)
    monkeypatch.setattr("shutil.disk_usage", lambda _: type("U", (), {"free": 2**20})())
    with pytest.raises(ConfigError, match=r"of disk .* more than the 1 MiB free for .*out"):
        check_budget(study, measured)
    monkeypatch.setenv(DISK_VARIABLE, "1GiB")
    needs = check_budget(study, measured)
    assert np.isfinite(sum(n.disk for n in needs))


def test_the_screening_counts_where_the_study_screens(tmp_path: Path) -> None:
    """``trajectories x (parameters + 1)`` runs, counted only for a study with candidates
    or a [screening] section (``bayescal screen`` checks its own part in any case)."""
    plain = load_study(_wall(tmp_path / "plain"))
    measured = load_measured(plain)
    assert "screening" not in {need.what for need in estimate(plain, measured)}
    screened = "[screening]\ntrajectories = 12\n\n[calibration]"
    sections = load_study(_wall(tmp_path / "section", ("[calibration]", screened)))
    heat = 'targets = ["concrete.specific_heat"]'
    candidate = (heat, f"{heat}\nscreen = true")
    flagged = load_study(_wall(tmp_path / "flagged", candidate))
    for study, trajectories in ((sections, 12), (flagged, 10)):
        needs = {need.what: need for need in estimate(study, measured)}
        need = needs["screening"]
        assert need.key == "screening.trajectories"
        runs = trajectories * (3 + 1)  # the wall's 3 parameters, candidates included
        assert need.memory >= 2 * runs * measured.n * 8
        assert need.disk >= runs * measured.n * 8


def test_the_message_names_the_key_out_of_proportion(tmp_path: Path) -> None:
    """chains x samples: the key further above its default is named."""
    cases = {
        ("chains = 4", "chains = 100000000"): "calibration.chains = 100000000",
        ("samples = 2000", "samples = 1000000000000"): "calibration.samples = 1000000000000",
    }
    for k, (edit, named) in enumerate(cases.items()):
        study = load_study(_wall(tmp_path / str(k), edit))
        measured = load_measured(study)
        with pytest.raises(ConfigError) as info:
            check_budget(study, measured)
        assert str(info.value).count(named) == 1
        assert f"lower {named.split(' = ')[0]}," in str(info.value)


def test_the_time_estimate_scales_with_the_chains_and_warns_past_an_hour(tmp_path: Path) -> None:
    study = load_study(_wall(tmp_path / "4"))
    measured = load_measured(study)
    plain = estimate_time(study, measured)
    parts = {part.what: part for part in plain.parts}
    assert set(parts) == {"emulator", "calibration"}
    assert parts["calibration"].detail == "4 chains × 3000 sweeps × 5 coordinates"
    # the shipped example runs its emulator and MCMC in about half a minute here
    assert 5.0 < plain.seconds < 300.0
    assert plain.warning() is None
    assert plain.simulator_runs == 30 + 50  # the design and the predict runs, not timed
    many = load_study(_wall(tmp_path / "10000", ("chains = 4", "chains = 10000")))
    big = estimate_time(many, measured)
    by = {part.what: part for part in big.parts}
    assert by["calibration"].seconds == pytest.approx(2500 * parts["calibration"].seconds)
    assert by["emulator"].seconds == parts["emulator"].seconds
    warning = big.warning()
    assert warning is not None
    assert warning.startswith("calibration.chains: the calibration alone may take about ")
    assert "10000 chains × 3000 sweeps" in warning
    assert "lower calibration.chains" in warning
    assert format_seconds(40) == "40 s"
    assert format_seconds(12 * 3600) == "12 h"


def test_the_time_estimate_counts_the_emulators_chains_and_the_difference_process(
    tmp_path: Path,
) -> None:
    base = load_study(_wall(tmp_path / "a"))
    measured = load_measured(base)
    mcmc = load_study(_wall(tmp_path / "b", ("[emulator]", '[emulator]\ntraining = "mcmc"')))
    emulator = {p.what: p for p in estimate_time(mcmc, measured).parts}["emulator"]
    assert emulator.key == "emulator.burn"  # 500 of 500, samples 500 of 1000 by default
    assert emulator.detail.startswith("2 chains × 1000 sweeps × ")
    longer = load_study(
        _wall(
            tmp_path / "c",
            ("[emulator]", '[emulator]\ntraining = "mcmc"'),
            ("samples = 500", "samples = 5000"),
        )
    )
    slower = {p.what: p for p in estimate_time(longer, measured).parts}["emulator"]
    assert slower.seconds == pytest.approx(emulator.seconds * (500 + 5000) / (500 + 500))
    assert slower.key == "emulator.samples"
    delta = load_study(
        _wall(tmp_path / "d", ("[calibration]", "[discrepancy]\nenabled = true\n\n[calibration]"))
    )
    parts = {p.what: p for p in estimate_time(delta, measured).parts}
    assert parts["difference process"].seconds == pytest.approx(parts["calibration"].seconds)
    ar1 = (
        'calibrate = ["heat_flux_in"]',
        'calibrate = ["heat_flux_in"]\nerrors.heat_flux_in.model = "ar1"',
    )
    with_phi = {
        p.what: p for p in estimate_time(load_study(_wall(tmp_path / "e", ar1)), measured).parts
    }
    assert with_phi["calibration"].detail.endswith("× 6 coordinates")  # and phi


def test_run_says_the_warning_before_its_first_stage(tmp_path: Path) -> None:
    long_chains = (
        "chains = 4\nburn = 1000\nsamples = 2000",
        "chains = 10000\nburn = 900\nsamples = 100",
    )
    study = load_study(_wall(tmp_path, long_chains))
    said: list[str] = []
    run(study, until="design", options=Options(backend="serial"), say=said.append)
    assert said[0].startswith("warning: calibration.chains: the calibration alone may take")
    assert said[1] == "design: running"
