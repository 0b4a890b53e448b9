"""Stage keys are pinned: an output folder written by an earlier bayescal is reused, not redone.

The keys below were computed for the shipped wall example before the pipeline
was split into modules (issue 14). A change of a key makes every existing
output folder recompute that stage and all later ones; if a change is meant,
say so in the release notes and update the pins.
"""

from __future__ import annotations

from pathlib import Path

from bayescal.config import load_study
from bayescal.examples import copy_example
from bayescal.pipeline import stage_keys
from bayescal.pipeline.keys import derived_seed, digest
from bayescal.pipeline.stages import prepare

WALL_KEYS = {
    "design": "f6f8f90cb6d42091ec14444ed9519babadc3b00636b47031c80800ebd3bd120a",
    "simulate": "5aec5b7637357200c8d3fc1fccce44ff078c2374c66f6b423e65a0c82c1c0537",
    "emulator": "ee3f299daf19e6374ee6500c965cbfa263c854b65b32b601d002c03f7ba144f9",
    "calibrate": "d283fe7d4fbcda257f87343b3484714cfd2153876616898186058dc5e7cf049a",
    "discrepancy": "8bc83317343973e926b2fc63d82ddfd02a6168326c39385a14594aec22011be4",
    "predict": "e02aac4b08a49a21423309b794692451ce4ee8c1f50752a3788200672d701a97",
    "report": "15cc4e75eccfa5528d98520265e9ffd498e8b95f82af5e2ab9dcd61334cbf44c",
}


def test_stage_keys_of_the_wall_example_are_pinned(tmp_path: Path) -> None:
    folder = copy_example("wall", tmp_path / "wall")
    assert stage_keys(prepare(load_study(folder))) == WALL_KEYS


def test_keys_do_not_depend_on_where_the_study_lives(tmp_path: Path) -> None:
    here = copy_example("wall", tmp_path / "a" / "wall")
    there = copy_example("wall", tmp_path / "b" / "elsewhere")
    assert stage_keys(prepare(load_study(here))) == stage_keys(prepare(load_study(there)))


def test_digest_and_derived_seed_are_pinned() -> None:
    assert digest("a", 1, [1.5, None]) == (
        "db8752fbe5082ff5f97db08920bb4731e7fe5bb6e0917915cd3832c3f9b5cd0e"
    )
    assert derived_seed(20240601, "calibrate") == 529508374
