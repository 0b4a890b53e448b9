"""A stage run again says why: the inputs of its key that changed, --from, or an
earlier stage that ran again (bayescal.pipeline.run, store.stages)."""

from __future__ import annotations

import json
from pathlib import Path

from bayescal.config import load_study
from bayescal.examples import copy_example
from bayescal.pipeline import Options, run
from bayescal.store.stages import RECORD

SERIAL = Options(backend="serial")


def _edit(folder: Path, old: str, new: str) -> None:
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    assert old in text
    path.write_text(text.replace(old, new), encoding="utf-8")


def _run(folder: Path, from_stage: str | None = None) -> list[str]:
    """What the stages said (their first line), up to the simulations."""
    said: list[str] = []
    study = load_study(folder)
    run(study, from_stage=from_stage, until="simulate", options=SERIAL, say=said.append)
    return [line.split(" (ran ")[0] for line in said if line.startswith(("design:", "simulate:"))
            and ("running" in line or "reused" in line)]  # fmt: skip


def test_a_changed_prior_names_the_parameter_and_the_stages_after_it(tmp_path: Path) -> None:
    folder = copy_example("wall", tmp_path / "wall")
    assert _run(folder) == ["design: running", "simulate: running"]  # a first run: no reason
    assert _run(folder) == ["design: up to date, reused", "simulate: up to date, reused"]
    # the prior's shape of cp_fb: the design's points move, so the runs are new
    beta = 'prior = { distribution = "beta", a = 2.0, b = 2.0, lower = 672.0'
    _edit(folder, 'prior = { distribution = "uniform", lower = 672.0', beta)
    assert _run(folder) == [
        "design: running (inputs changed: parameters.cp_fb)",
        "simulate: running (inputs changed: the design stage)",
    ]
    _edit(folder, "runs = 30", "runs = 31\n\n[runner]\nretries = 2")
    assert _run(folder) == [
        "design: running (inputs changed: design.runs)",
        "simulate: running (inputs changed: the design stage, runner.retries)",
    ]
    log = (folder / "out" / "bayescal.log").read_text(encoding="utf-8")
    assert "design: running (inputs changed: design.runs)" in log
    record = json.loads((folder / "out" / RECORD).read_text(encoding="utf-8"))
    assert set(record["design"]["inputs"]) >= {"parameters", "parameters.cp_fb", "design.runs"}


def test_from_an_earlier_stage_and_an_old_record_are_said(tmp_path: Path) -> None:
    folder = copy_example("wall", tmp_path / "wall")
    _run(folder)
    assert _run(folder, from_stage="simulate") == [
        "design: up to date, reused",
        "simulate: running (--from simulate)",
    ]
    # the design's file is damaged: it runs again with the same key, and so does what follows
    (folder / "out" / "design.csv").write_text("garbage", encoding="utf-8")
    said = _run(folder)
    assert said[0] == "design: running"  # the warning before it said why
    assert said[1] == "simulate: running (after design ran again)"
    # a record written before the inputs were kept: the stage says it cannot tell which
    path = folder / "out" / RECORD
    record = json.loads(path.read_text(encoding="utf-8"))
    for stage in record.values():
        stage.pop("inputs")
    path.write_text(json.dumps(record), encoding="utf-8")
    _edit(folder, "runs = 30", "runs = 32")
    assert _run(folder)[0] == (
        "design: running (its inputs changed; the record of its last run, from an earlier "
        "bayescal, does not say which)"
    )
