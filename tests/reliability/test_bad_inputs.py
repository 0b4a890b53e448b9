"""The bad-input corpus: every broken study fails with one clear line, never a traceback.

The cases live in ``tests/reliability/bad_inputs/cases.toml`` (its header documents the
format). Each one copies the shipped wall example into a temporary folder,
converts its data to the case's format, breaks one thing and runs the command
line in-process. The promise checked for every case: exit status 2, nothing on
stdout, exactly one line ``error: ...`` on stderr without a traceback, naming
the file or key at fault and holding the expected fragments, and no file
written into the study folder (no half-written output, no temporary file).

A few problems only show in later stages (a design that does not vary the
output); they are checked on the Python functions at the end of this file.
"""

from __future__ import annotations

import shutil
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.design import UniformPrior, latin_hypercube
from bayescal.emulator.assemble import assemble
from bayescal.emulator.basis import pca_basis
from bayescal.errors import DataError
from bayescal.periods import layout_periods
from faults import refuse_writes
from paths import REPO

HERE = Path(__file__).resolve().parent
WALL = REPO / "src" / "bayescal" / "examples" / "wall"
MANIFEST = tomllib.loads((HERE / "bad_inputs" / "cases.toml").read_text(encoding="utf-8"))
PRESETS: dict[str, str] = {name: p["data"] for name, p in MANIFEST["preset"].items()}
EXTENSIONS = {"csv": "csv", "parquet": "parquet", "modelica": "txt", "epw": "epw"}
ZONE = "UTC-06:00"  # the wall example's data.time_zone
EPOCH = pd.Timestamp("2013-01-12T00:00:00")  # first local time of the wall data
UNIX = pd.Timestamp("1970-01-01")


@dataclass(frozen=True)
class Case:
    """One entry of the manifest."""

    id: str
    where: str
    expect: list[str]
    preset: str = "csv"
    args: list[str] = field(default_factory=lambda: ["validate", "{study}"])
    study: list[list[str]] = field(default_factory=list)
    frame: list[dict[str, Any]] = field(default_factory=list)
    text: list[dict[str, Any]] = field(default_factory=list)
    bytes: list[dict[str, Any]] = field(default_factory=list)
    write: dict[str, str] = field(default_factory=dict)
    write_hex: dict[str, str] = field(default_factory=dict)
    mkdir: list[str] = field(default_factory=list)
    remove: list[str] = field(default_factory=list)
    study_encoding: str = "utf-8"
    inject: dict[str, str] = field(default_factory=dict)


CASES = [Case(**entry) for entry in MANIFEST["case"]]
GOOD = [Case(where="", **entry) for entry in MANIFEST["good"]]


# --------------------------------------------------------------------------- the data table


def _wall_table() -> pd.DataFrame:
    """The wall example's data as strings, exactly as written in the file."""
    return pd.read_csv(WALL / "data" / "wall.csv", dtype=str, keep_default_na=False)


def _apply_frame(table: pd.DataFrame, ops: list[dict[str, Any]]) -> pd.DataFrame:
    for op in ops:
        kind = op["op"]
        rows = slice(*op["rows"]) if "rows" in op else slice(None)
        if kind == "set":
            table.loc[table.index[rows], op["column"]] = op["value"]
        elif kind == "head":
            table = table.head(op["n"])
        elif kind == "every":
            table = table.iloc[:: op["k"]]
        elif kind == "drop":
            table = table.drop(table.index[rows])
        elif kind == "swap":
            order = list(range(len(table)))
            order[op["a"]], order[op["b"]] = order[op["b"]], order[op["a"]]
            table = table.iloc[order]
        elif kind == "dup":
            table = pd.concat([table.iloc[: op["row"] + 1], table.iloc[op["row"] :]])
        elif kind == "rename":
            table = table.rename(columns={op["old"]: op["new"]})
        elif kind == "shift":
            times = pd.to_datetime(table["time"].iloc[rows]) + pd.Timedelta(op["by"])
            table.iloc[rows, 0] = times.dt.strftime("%Y-%m-%d %H:%M").to_numpy()
        elif kind == "suffix":
            table.iloc[rows, 0] = (table["time"].iloc[rows] + op["text"]).to_numpy()
        elif kind == "epoch":  # local times of the wall's zone -> seconds since 1970 UTC
            utc = pd.to_datetime(table["time"]) + pd.Timedelta(hours=6)  # ZONE is UTC-06:00
            table["time"] = (utc - UNIX).dt.total_seconds().astype(int).astype(str)
        elif kind == "jitter":  # a logger clock wandering by up to ±seconds
            rng = np.random.default_rng(op["seed"])
            shift = pd.to_timedelta(
                rng.integers(-op["seconds"], op["seconds"] + 1, len(table)), "s"
            )
            times = pd.to_datetime(table["time"]) + shift
            table["time"] = times.dt.strftime("%Y-%m-%d %H:%M:%S").to_numpy()
        else:
            raise AssertionError(f"unknown frame op {kind!r}")
        table = table.reset_index(drop=True)
    return table


def _numbers(column: pd.Series) -> pd.Series:
    """A column as floats if every cell is a number, else the strings."""
    converted = pd.to_numeric(column, errors="coerce")
    return converted if not converted.isna().any() else column


def _write_parquet(table: pd.DataFrame, path: Path) -> None:
    first = table.columns[0]  # the time column, whatever a case renamed it to
    out = {first: pd.to_datetime(table[first], errors="coerce")}
    out |= {name: _numbers(table[name]) for name in table.columns[1:]}
    pd.DataFrame(out).to_parquet(path, index=False)


def _modelica_text(table: pd.DataFrame) -> str:
    seconds = (pd.to_datetime(table["time"]) - EPOCH).dt.total_seconds().astype(int)
    rows = [
        " ".join([str(s), *cells])
        for s, cells in zip(seconds, table.iloc[:, 1:].values, strict=True)
    ]
    return f"#1\ndouble wall({len(rows)},{table.shape[1]})\n" + "\n".join(rows) + "\n"


_EPW_HEADER = [
    "LOCATION,Chicago Ohare Intl Ap,IL,USA,TMY3,725300,41.98,-87.92,-6.0,201.0",
    "DESIGN CONDITIONS,0",
    "TYPICAL/EXTREME PERIODS,0",
    "GROUND TEMPERATURES,0",
    "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0",
    "COMMENTS 1,bayescal bad-input corpus",
    "COMMENTS 2,wall example data on the hour",
    "DATA PERIODS,1,1,Data,Saturday,1/12,2/15",
]


def _epw_text(table: pd.DataFrame) -> str:
    """The wall data on the hour as an EPW file (hour field = hour ending, local time)."""
    times = pd.to_datetime(table["time"])
    on_hour = table[times.dt.minute == 0]
    lines = list(_EPW_HEADER)
    for stamp, (_, row) in zip(times[times.dt.minute == 0], on_hour.iterrows(), strict=True):
        day = stamp - pd.Timedelta(hours=1) if stamp.hour == 0 else stamp
        hour = 24 if stamp.hour == 0 else stamp.hour
        fields = [day.year, day.month, day.day, hour, 60, "?9?9?9?9E0?9?9?9"]
        fields += [row["T_se"], row["T_si"], 80, 99000, 0, 1415, 250, row["q_si"], 0, 0]
        fields += [0, 0, 0, 0, 270, 3.1, 10, 10, 16.1, 77777, 9, 999999999, 10, 0.1, 0, 88]
        fields += [0.2, 0, 1.0]
        lines.append(",".join(str(f) for f in fields))
    return "\n".join(lines) + "\n"


def _apply_text(text: str, ops: list[dict[str, Any]]) -> str:
    for op in ops:
        kind = op["op"]
        if kind == "sub":
            assert op["old"] in text, f"text op {op} matches nothing"
            text = text.replace(op["old"], op["new"])
        elif kind == "cut":
            cut = int(len(text) * op["at"])
            text = text[:cut] if text[cut - 1] not in ",\n" else text[: cut - 2]
        elif kind == "lines":
            text = "".join(text.splitlines(keepends=True)[: op["stop"]])
        elif kind == "line":
            lines = text.splitlines(keepends=True)
            lines[op["line"] - 1] = op["text"] + "\n"
            text = "".join(lines)
        else:
            raise AssertionError(f"unknown text op {kind!r}")
    return text


def _apply_bytes(path: Path, ops: list[dict[str, Any]]) -> None:
    data = path.read_bytes()
    for op in ops:
        if op["op"] == "cut":
            data = data[: int(len(data) * op["at"])]
        elif op["op"] == "garbage":
            data = np.random.default_rng(len(data)).bytes(op["n"])
        elif op["op"] == "encode":  # the text saved in another encoding (Excel's UTF-16)
            data = data.decode("utf-8").encode(op["encoding"])
        else:
            raise AssertionError(f"unknown bytes op {op['op']!r}")
    path.write_bytes(data)


# --------------------------------------------------------------------------- building a case


def _replace_data_section(toml: str, section: str) -> str:
    start, end = toml.index("\n[data]\n"), toml.index("\n[simulator]\n")
    return toml[:start] + "\n" + section.strip() + "\n" + toml[end:]


def build_study(case: Case, tmp_path: Path) -> Path:
    """The wall example in ``tmp_path/study``, with the case's changes applied."""
    folder = tmp_path / "study"
    shutil.copytree(WALL, folder, ignore=shutil.ignore_patterns("out", "README.md"))
    toml = (folder / "study.toml").read_text(encoding="utf-8")
    data = folder / "data" / f"wall.{EXTENSIONS[case.preset]}"
    if case.preset != "csv":
        (folder / "data" / "wall.csv").unlink()
        toml = _replace_data_section(toml, PRESETS[case.preset])
    for old, new in case.study:
        assert old in toml, f"{case.id}: {old!r} is not in study.toml"
        toml = toml.replace(old, new)
    (folder / "study.toml").write_text(toml, encoding=case.study_encoding)
    table = _apply_frame(_wall_table(), case.frame)
    if case.preset == "parquet":
        _write_parquet(table, data)
    else:
        writers = {"csv": lambda t: t.to_csv(index=False), "modelica": _modelica_text}
        text = (writers | {"epw": _epw_text})[case.preset](table)
        data.write_text(_apply_text(text, case.text), encoding="utf-8")
    _apply_bytes(data, case.bytes)
    for name, text in case.write.items():
        (folder / name).write_text(text, encoding="utf-8")
    for name, hexed in case.write_hex.items():
        (folder / name).write_bytes(bytes.fromhex(hexed))
    for name in case.remove:
        (folder / name).unlink()
    for name in case.mkdir:
        (folder / name).unlink(missing_ok=True)
        (folder / name).mkdir()
    return folder


def run_cli(args: list[str], folder: Path) -> tuple[int, str, str]:
    """Run ``bayescal ARGS`` in-process; {study}, {file} and {data} are filled in."""
    filled = [a.replace("{study}", str(folder)) for a in args]
    result = CliRunner().invoke(main, filled)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception  # a bug: let pytest show its traceback
    return result.exit_code, result.stdout, result.stderr


def _files(folder: Path) -> set[Path]:
    return {p.relative_to(folder) for p in folder.rglob("*")}


# --------------------------------------------------------------------------- the corpus


def test_corpus_is_large_and_ids_are_unique() -> None:
    ids = [case.id for case in CASES]
    assert len(ids) >= 40
    assert len(set(ids)) == len(ids)


@pytest.mark.parametrize("preset", ["csv", *PRESETS])
def test_unbroken_presets_validate(preset: str, tmp_path: Path) -> None:
    """Each format's unbroken copy is valid, so each case fails for its own change."""
    folder = build_study(Case(id=preset, where="", expect=[], preset=preset), tmp_path)
    code, out, err = run_cli(["validate", "{study}"], folder)
    assert code == 0, err
    assert "training periods" in out


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_gives_one_clear_line(
    case: Case, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = build_study(case, tmp_path)
    before = _files(folder)
    if case.inject:
        refuse_writes(monkeypatch, folder / case.inject["under"], case.inject["errno"])
    code, out, err = run_cli(case.args, folder)
    assert code == 2, f"exit {code}; stdout {out!r}; stderr {err!r}"
    assert out == ""
    assert err.startswith("error: ")
    assert err.count("\n") == 1, err
    assert err.endswith("\n")
    assert "Traceback" not in err
    assert case.where in err, f"the message does not name {case.where!r}: {err}"
    for fragment in case.expect:
        assert fragment in err, f"{fragment!r} not in {err}"
    assert _files(folder) == before, "files were written into the study folder"


@pytest.mark.parametrize("case", GOOD, ids=[c.id for c in GOOD])
def test_inputs_users_produce_that_are_accepted(case: Case, tmp_path: Path) -> None:
    """What real users produce and bayescal reads (``[[good]]`` in the manifest): the
    command succeeds and says what it did with the input."""
    folder = build_study(case, tmp_path)
    code, out, err = run_cli(case.args, folder)
    assert code == 0, err
    assert "training periods" in out
    for fragment in case.expect:
        assert fragment in out, f"{fragment!r} not in {out}"


def test_debug_flag_shows_the_traceback_instead(tmp_path: Path) -> None:
    case = next(c for c in CASES if c.id == "csv-duplicated-timestamps")
    folder = build_study(case, tmp_path)
    result = CliRunner().invoke(main, ["--debug", "validate", str(folder)])
    assert result.exit_code == 2
    assert "Traceback" in result.stderr
    assert "DataError" in result.stderr


def test_console_script_prints_one_line(tmp_path: Path) -> None:
    """The installed entry point behaves like the in-process runs above."""
    import subprocess
    import sys

    script = Path(sys.executable).parent / "bayescal"
    if not script.is_file():
        pytest.skip(f"console script {script} is not installed")
    case = next(c for c in CASES if c.id == "csv-truncated-mid-row")
    folder = build_study(case, tmp_path)
    done = subprocess.run([str(script), "validate", str(folder)], capture_output=True, text=True)
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.count("\n") == 1
    assert "wall.csv" in done.stderr


# --------------------------------------------------------------------------- later stages


def test_pca_of_identical_periods_is_a_clear_error() -> None:
    y = np.zeros((24, 10))  # every standardised period identical: no variance at all
    with pytest.raises(DataError, match="no variance"):
        pca_basis(y)


def test_assemble_with_output_that_ignores_the_parameters() -> None:
    """A design whose runs all give the same output cannot be standardised."""
    priors = {"a": UniformPrior(0.0, 1.0), "b": UniformPrior(0.0, 1.0)}
    design = latin_hypercube(priors, 8, seed=3)
    n = 24 * 5
    t = np.arange(n)
    same = np.tile(np.sin(2 * np.pi * t / 24), (design.runs, 1))
    layout = layout_periods(n, 24, 24, 24)
    with pytest.raises(DataError, match=r"same in all .* simulated periods"):
        assemble(
            design,
            {"heat_flux_in": same},
            {"heat_flux_in": np.sin(2 * np.pi * t / 24)},
            {"temp_air_out": np.cos(2 * np.pi * t / 24)},
            layout,
        )
