"""Times of a study in the hour that a daylight-saving change repeats or skips.

``[data] start``, ``end``, ``epoch``, ``[[data.exclude]]`` windows, ``[periods]
train_from`` and the ``--from``/``--to`` options are local times of ``[data]
time_zone``. In Europe/Berlin 2013-10-27T02:30 occurs twice and 2013-03-31T02:30
does not exist: each is a one-line ``ConfigError`` naming the key or option, the
time, both UTC instants or the skipped hour, and how to fix it; never pandas'
bare ValueError with a traceback.
"""

from __future__ import annotations

import copy
import shutil
import tomllib
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import tomli_w
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.clock import local_time_problem, local_to_utc, parse_time_zone
from bayescal.config import load_study, study_from_dict
from bayescal.data.measured import load_measured
from bayescal.errors import ConfigError
from bayescal.pipeline import update as update_module
from paths import FIXTURES

FIXTURE = FIXTURES / "wall-study"
BASE = tomllib.loads((FIXTURE / "study.toml").read_text(encoding="utf-8"))
BERLIN = parse_time_zone("Europe/Berlin")
REPEATED, SKIPPED = "2013-10-27T02:30:00", "2013-03-31T02:30:00"
BOTH = "it is 2013-10-27 00:30 UTC (UTC+02:00) or 2013-10-27 01:30 UTC (UTC+01:00)"
GAP = "whose clocks skip an hour from 02:00 to 03:00 on 2013-03-31"


def _berlin(key: str, value: str, fmt: str = "csv") -> dict[str, Any]:
    """The fixture study in Europe/Berlin with ``key`` (``"data.start"``,
    ``"data.exclude.start"``, ``"periods.train_from"``...) set to ``value``."""
    raw = copy.deepcopy(BASE)
    raw["data"]["time_zone"] = "Europe/Berlin"
    if key == "data.epoch":  # a Modelica table
        raw["data"] = {k: v for k, v in raw["data"].items() if k != "time_column"}
        raw["data"] |= {"format": "modelica", "file": "wall.txt"}
        for i, spec in enumerate(raw["data"]["columns"].values()):
            spec["source"] = i + 1
    section, _, name = key.partition(".")
    if name.startswith("exclude."):
        window = {"start": "2013-06-01T00:00:00", "end": "2013-12-01T00:00:00"}
        raw["data"]["exclude"] = [window | {name.split(".")[1]: value}]
    else:
        raw[section][name] = value
    return raw


KEYS = [
    ("data.start", "data.start"),
    ("data.end", "data.end"),
    ("data.epoch", "data.epoch"),
    ("data.exclude.start", "data.exclude[0].start"),
    ("data.exclude.end", "data.exclude[0].end"),
    ("periods.train_from", "periods.train_from"),
]


@pytest.mark.parametrize(("key", "named"), KEYS)
def test_a_study_time_the_clocks_repeat_is_a_config_error_with_both_instants(
    key: str, named: str
) -> None:
    with pytest.raises(ConfigError) as info:
        study_from_dict(_berlin(key, REPEATED), root=FIXTURE)
    text = info.value.one_line()
    assert f"{named}: {REPEATED} occurs twice in time zone Europe/Berlin" in text
    assert BOTH in text
    assert f"'{REPEATED}+02:00' or '{REPEATED}+01:00'" in text
    assert "\n" not in text


@pytest.mark.parametrize(("key", "named"), KEYS)
def test_a_study_time_the_clocks_skip_is_a_config_error_with_a_fix(key: str, named: str) -> None:
    raw = _berlin(key, SKIPPED)
    if key == "data.exclude.end":
        raw["data"]["exclude"][0]["start"] = "2013-01-01T00:00:00"
    with pytest.raises(ConfigError) as info:
        study_from_dict(raw, root=FIXTURE)
    text = info.value.one_line()
    assert f"{named}: {SKIPPED} does not exist in time zone Europe/Berlin, {GAP}" in text
    assert "give a time outside the skipped hour (e.g. '2013-03-31T03:00:00', 01:00 UTC)" in text
    assert "set data.time_zone to its fixed offset 'UTC+01:00'" in text


@pytest.mark.parametrize(("key", "named"), KEYS)
@pytest.mark.parametrize(
    "value", ["2013-10-27T03:30:00", "2013-10-27T02:30:00+01:00", "2013-03-31T03:00:00"]
)
def test_a_time_outside_the_change_or_with_its_offset_is_accepted(
    key: str, named: str, value: str
) -> None:
    raw = _berlin(key, value)
    if key == "data.exclude.end":
        raw["data"]["exclude"][0]["start"] = "2013-01-01T00:00:00"
    study_from_dict(raw, root=FIXTURE)


def test_a_fixed_offset_zone_has_no_such_hour_and_order_is_still_checked() -> None:
    raw = _berlin("data.start", REPEATED)
    raw["data"]["time_zone"] = "UTC+01:00"
    study_from_dict(raw, root=FIXTURE)
    raw["data"]["end"] = "2013-10-27T02:00:00"
    with pytest.raises(ConfigError, match=r"data\.end: 2013-10-27 02:00:00 is not after"):
        study_from_dict(raw, root=FIXTURE)


@pytest.mark.parametrize(
    ("zone", "time", "expected"),
    [
        ("Europe/Berlin", "2013-10-27T02:00:00", "occurs twice"),
        ("Europe/Berlin", "2013-10-27T03:00:00", None),
        ("Europe/Berlin", "2013-03-31T02:00:00", GAP),
        ("Europe/Berlin", "2013-03-31T01:59:00", None),
        ("America/Chicago", "2013-11-03T01:30:00", "06:30 UTC (UTC-05:00) or 2013-11-03 07:30"),
        ("America/Chicago", "2013-03-10T02:59:00", "skip an hour from 02:00 to 03:00"),
        # half an hour; pandas' nonexistent="shift_forward" would move it a whole hour
        ("Australia/Lord_Howe", "2013-10-06T02:10:00", "by 30 minutes from 02:00 to 02:30"),
        ("Australia/Lord_Howe", "2013-04-07T01:40:00", "go back by 30 minutes"),
        # two hours (pandas' "shift_backward" assumes one), and a whole day skipped
        ("Antarctica/Troll", "2013-03-31T01:30:00", "skip by 2 hours from 01:00 to 03:00"),
        ("Pacific/Apia", "2011-12-30T12:00:00", "skip by 24 hours from 00:00 to 00:00"),
        ("UTC+01:00", "2013-10-27T02:30:00", None),
    ],
)
def test_local_time_problem_says_what_the_clocks_do(
    zone: str, time: str, expected: str | None
) -> None:
    problem = local_time_problem(datetime.fromisoformat(time), parse_time_zone(zone))
    if expected is None:
        assert problem is None
    else:
        assert problem is not None
        assert expected in problem[0]


def test_local_to_utc_names_the_option_and_leaves_offsets_alone() -> None:
    with pytest.raises(ConfigError, match=r"^--from: 2013-10-27T02:30:00 occurs twice"):
        local_to_utc(pd.Timestamp(REPEATED), BERLIN, "--from")
    aware = local_to_utc(pd.Timestamp(f"{REPEATED}+01:00"), BERLIN, "--from")
    assert aware == pd.Timestamp("2013-10-27T01:30:00Z")
    assert local_to_utc(pd.Timestamp("2013-10-27T03:30"), BERLIN, "x") == aware + pd.Timedelta("1h")


def _across_the_change(folder: Path, train_from: str) -> Path:
    """The fixture's six days moved across the end of summer time 2012 in Berlin (the
    file writes the repeated hour twice), trained from ``train_from``."""
    shutil.copytree(FIXTURE, folder)
    frame = pd.read_csv(folder / "wall.csv")
    utc = pd.date_range("2012-10-25T22:00Z", periods=len(frame), freq="30min")
    frame["time"] = utc.tz_convert(BERLIN).strftime("%Y-%m-%dT%H:%M:%S")
    frame.to_csv(folder / "wall.csv", index=False)
    raw = copy.deepcopy(BASE)
    raw["data"]["time_zone"] = "Europe/Berlin"
    raw["periods"]["train_from"] = train_from
    (folder / "study.toml").write_text(tomli_w.dumps(raw), encoding="utf-8")
    return folder


def test_a_record_across_the_change_trains_from_a_time_given_with_its_offset(
    tmp_path: Path,
) -> None:
    """The record before ``train_from`` (the layout's warm-up) ends at the 02:00 meant:
    the first (00:00 UTC) or the second (01:00 UTC) of 2012-10-28."""
    with pytest.raises(ConfigError, match=r"periods\.train_from: 2012-10-28T02:00:00 occurs"):
        load_study(_across_the_change(tmp_path / "naive", "2012-10-28T02:00:00"))
    second = load_measured(load_study(_across_the_change(tmp_path / "b", "2012-10-28T02:00+01:00")))
    first = load_measured(load_study(_across_the_change(tmp_path / "a", "2012-10-28T02:00+02:00")))
    assert first.times[first.layout.warmup] == np.datetime64("2012-10-28T00:00")
    assert second.times[second.layout.warmup] == np.datetime64("2012-10-28T01:00")


def test_an_update_writes_a_repeated_local_time_with_its_offset() -> None:
    """``bayescal update`` writes the previous test window's start as a local time; in
    the repeated hour it carries its offset, so that the update's study file loads."""
    local = update_module._local
    assert local(np.datetime64("2013-10-27T00:30"), BERLIN) == "2013-10-27T02:30:00+02:00"
    assert local(np.datetime64("2013-10-27T01:30"), BERLIN) == "2013-10-27T02:30:00+01:00"
    assert local(np.datetime64("2013-10-27T02:30"), BERLIN) == "2013-10-27T03:30:00"
    raw = _berlin("periods.train_from", local(np.datetime64("2013-10-27T01:30"), BERLIN))
    study = study_from_dict(raw, root=FIXTURE)
    assert local_to_utc(study.periods.train_from, BERLIN, "x") == pd.Timestamp("2013-10-27T01:30Z")


def _cli_folder(tmp_path: Path, key: str = "data.time_zone", value: str = "Europe/Berlin") -> Path:
    folder = tmp_path / "study"
    shutil.copytree(FIXTURE, folder)
    raw = _berlin(key, value)
    (folder / "study.toml").write_text(tomli_w.dumps(raw), encoding="utf-8")
    return folder


def _one_line(args: list[str]) -> str:
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2, res.output
    assert res.output.count("\n") == 1, res.output
    assert "Traceback" not in res.output
    assert res.output.startswith("error: ")
    return res.output


@pytest.mark.parametrize(
    ("key", "value"), [("data.start", REPEATED), ("periods.train_from", SKIPPED)]
)
def test_cli_validate_prints_one_line_for_a_study_time(
    tmp_path: Path, key: str, value: str
) -> None:
    out = _one_line(["validate", str(_cli_folder(tmp_path, key, value))])
    assert f"{key}: {value} " in out
    assert BOTH in out if value == REPEATED else GAP in out


@pytest.mark.parametrize("option", ["--from", "--to"])
@pytest.mark.parametrize("value", [REPEATED, SKIPPED])
def test_cli_predict_names_the_window_option(tmp_path: Path, option: str, value: str) -> None:
    folder = _cli_folder(tmp_path)
    out = _one_line(["predict", str(folder), "--data", str(folder / "wall.csv"), option, value])
    assert f"error: {option}: {value} " in out
    assert BOTH in out if value == REPEATED else GAP in out


def test_cli_update_names_its_to_option(tmp_path: Path) -> None:
    out = _one_line(["update", str(_cli_folder(tmp_path)), "--to", SKIPPED])
    assert f"error: --to: {SKIPPED} does not exist in time zone Europe/Berlin, {GAP}" in out


@pytest.mark.parametrize("value", ["", "NaT", "nat"])
def test_cli_an_empty_or_nat_window_is_one_line(tmp_path: Path, value: str) -> None:
    """pandas reads these as no time at all (no ValueError): still a one-line error."""
    folder = _cli_folder(tmp_path)
    out = _one_line(["predict", str(folder), "--data", str(folder / "wall.csv"), "--from", value])
    assert f"error: --from {value!r} is not a date and time" in out
    out = _one_line(["update", str(folder), "--to", value])
    assert f"error: --to {value!r} is not a date and time" in out
