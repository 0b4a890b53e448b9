"""Corrupted artefacts (a disk that filled, a copy interrupted, a flipped bit) are detected,
said in one line and computed again: never used, never a traceback.

One short calibration of the wall example is run once; each test copies its
output folder, damages one file and runs (or shows) the study again.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import load_study
from bayescal.examples import copy_example
from bayescal.pipeline import Options, Results, run
from bayescal.pipeline.keys import stage_keys
from bayescal.pipeline.stages import prepare
from bayescal.runner.cache import load_run

SERIAL = Options(backend="serial", chains_backend="serial")
FAST = """
[emulator]
pca_variance = 0.999
burn = 100
samples = 100

[calibration]
chains = 4
burn = 100
samples = 200
max_samples = 200
"""
UNTIL = "calibrate"


@pytest.fixture(scope="module")
def done(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Results]:
    folder = copy_example("wall", tmp_path_factory.mktemp("corrupt") / "wall")
    text = (folder / "study.toml").read_text(encoding="utf-8")
    (folder / "study.toml").write_text(text[: text.index("[emulator]")] + FAST, "utf-8")
    return folder, run(load_study(folder), until=UNTIL, options=SERIAL)


def _copy(done: tuple[Path, Results], tmp_path: Path) -> Path:
    return Path(shutil.copytree(done[0], tmp_path / "wall"))


def _truncate(path: Path, fraction: float = 0.5) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])


def _flip(path: Path) -> None:
    """One bit flipped in the middle: same size, different content."""
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x10
    path.write_bytes(bytes(data))


def _again(folder: Path, from_stage: str | None = None) -> tuple[Results, list[str]]:
    notes: list[str] = []
    res = run(
        load_study(folder), from_stage=from_stage, until=UNTIL, options=SERIAL, say=notes.append
    )
    damage = [n for n in notes if "damaged" in n or " be read" in n]  # not the diagnostics
    assert all(n.startswith("warning: ") for n in damage)
    return res, damage


def _same_posterior(a: Results, b: Results) -> None:
    assert a.posterior is not None
    assert b.posterior is not None
    np.testing.assert_array_equal(a.posterior.draws, b.posterior.draws)


@pytest.mark.parametrize("damage", [_truncate, _flip], ids=["truncated", "bit-flip"])
def test_a_damaged_run_cache_file_is_run_again(
    done: tuple[Path, Results], tmp_path: Path, damage: object
) -> None:
    folder = _copy(done, tmp_path)
    runs = sorted((folder / "out" / "simulations" / "runs").glob("*.npz"))
    victim = runs[3]
    damage(victim)  # type: ignore[operator]
    assert load_run(victim, ("heat_flux_in",), 1644) is None  # CRC-32 or zip structure
    res, warnings = _again(folder, from_stage="simulate")
    assert res.simulations is not None
    assert res.simulations.damaged == (victim.stem,)
    assert res.simulations.n_cached == 29
    (line,) = warnings
    assert f"1 cached run(s) could not be read (e.g. simulations/runs/{victim.name}" in line
    assert load_run(victim, ("heat_flux_in",), 1644) is not None  # rewritten whole
    original = done[1].simulations
    assert original is not None
    np.testing.assert_array_equal(
        res.simulations.outputs["heat_flux_in"], original.outputs["heat_flux_in"]
    )
    _same_posterior(res, done[1])


@pytest.mark.parametrize("damage", [_truncate, _flip], ids=["truncated", "bit-flip"])
def test_a_damaged_emulator_is_computed_again(
    done: tuple[Path, Results], tmp_path: Path, damage: object
) -> None:
    folder = _copy(done, tmp_path)
    damage(folder / "out" / "emulator.nc")  # type: ignore[operator]
    res, warnings = _again(folder)
    (line,) = warnings
    assert "emulator: emulator.nc damaged (size or checksum differs" in line
    assert "computing the stage again" in line
    assert res.reused == ("design", "simulate")
    assert res.ran == ("emulator", "calibrate")
    _same_posterior(res, done[1])
    again, warnings = _again(folder)  # and now it is whole again
    assert warnings == []
    assert again.ran == ()


def test_without_recorded_checksums_a_damaged_file_fails_its_load_check(
    done: tuple[Path, Results], tmp_path: Path
) -> None:
    """Output folders written before checksums were kept: loading is the check."""
    folder = _copy(done, tmp_path)
    record = folder / "out" / "stages.json"
    stages = json.loads(record.read_text())
    for entry in stages.values():
        entry.pop("sha256", None)
        entry.pop("sizes", None)
    record.write_text(json.dumps(stages))
    _truncate(folder / "out" / "posterior.nc", 0.3)
    res, warnings = _again(folder)
    (line,) = warnings
    assert line.startswith("warning: calibrate: its files cannot be read back (")
    assert res.ran == ("calibrate",)
    _same_posterior(res, done[1])


def test_a_damaged_checkpoint_is_said_and_its_chain_starts_again(
    done: tuple[Path, Results], tmp_path: Path
) -> None:
    folder = _copy(done, tmp_path)
    key = stage_keys(prepare(load_study(folder)))["calibrate"]
    snapshots = folder / "out" / "checkpoints" / f"calibrate-{key[:16]}"
    snapshots.mkdir(parents=True)
    (snapshots / "chain-1.npz").write_bytes(b"PK\x03\x04 half a snapshot")
    res, warnings = _again(folder, from_stage="calibrate")
    (line,) = warnings
    assert f"calibrate: checkpoint checkpoints/calibrate-{key[:16]}/chain-1.npz is damaged" in line
    assert "starts again from the beginning" in line
    _same_posterior(res, done[1])


def test_show_refuses_a_damaged_artefact_in_one_line(
    done: tuple[Path, Results], tmp_path: Path
) -> None:
    folder = _copy(done, tmp_path)
    _flip(folder / "out" / "posterior.nc")
    result = CliRunner().invoke(main, ["show", str(folder)])
    assert result.exit_code == 2
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1
    assert "posterior.nc is damaged (its size or checksum differs" in result.stderr
    assert "computes the calibrate stage again" in result.stderr
