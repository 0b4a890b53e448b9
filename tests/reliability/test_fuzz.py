"""Property tests: random or mangled input raises only bayescal's own errors.

Each reader gets random bytes and random edits of a valid file; the study
loader gets random edits of a valid ``study.toml`` (as text) and random
changes of its parsed content (as a dict). Whatever arrives, the only
exception allowed out is a :class:`~bayescal.errors.BayescalError` (which the
command line prints as one line); anything else is a bug. Examples are kept
few (``MAX_EXAMPLES`` per property) so that the file runs in well under a
minute; set BAYESCAL_FUZZ_EXAMPLES for a deeper run. Hypothesis' database replays
failures first.
"""

from __future__ import annotations

import copy
import io
import os
import tomllib
from datetime import datetime
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayescal.config import load_study, study_from_dict
from bayescal.data import load_measured
from bayescal.data.readers import read_csv, read_epw, read_modelica_table, read_parquet
from bayescal.errors import BayescalError
from paths import REPO

WALL = REPO / "src" / "bayescal" / "examples" / "wall"
WALL_TOML = (WALL / "study.toml").read_text(encoding="utf-8")
WALL_CSV = (WALL / "data" / "wall.csv").read_text(encoding="utf-8")
SMALL_CSV = "".join(WALL_CSV.splitlines(keepends=True)[:60])
MAX_EXAMPLES = int(os.environ.get("BAYESCAL_FUZZ_EXAMPLES", "120"))  # more for a deep run
FUZZ = settings(
    max_examples=MAX_EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

SMALL_EPW = "\n".join(
    [
        "LOCATION,Somewhere,XX,XXX,TMY3,000000,50.8,4.3,1.0,100.0",
        "DESIGN CONDITIONS,0",
        "TYPICAL/EXTREME PERIODS,0",
        "GROUND TEMPERATURES,0",
        "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0",
        "COMMENTS 1,fuzz",
        "COMMENTS 2,fuzz",
        "DATA PERIODS,1,1,Data,Sunday,1/1,1/2",
    ]
    + [
        f"2013,1,{1 + h // 24},{h % 24 + 1},60,?9?9?9?9E0?9?9?9,{-2 + h * 0.1:.1f},-5.0,80,"
        f"101000,0,1415,250,{max(0, 300 - 20 * abs(h % 24 - 12))},0,0,0,0,0,0,270,3.1,10,10,"
        "16.1,77777,9,999999999,10,0.1,0,88,0.2,0,1.0"
        for h in range(48)
    ]
)
SMALL_MODELICA = "#1\n# fuzz table\ndouble tab(24,3)\n" + "".join(
    f"{3600 * h} {10 + 0.5 * h:.2f} {-4.0 + h * 0.25:.3f}\n" for h in range(24)
)

# Characters that mean something to one of the formats, plus anything at all.
SYNTAX = [*",;\t\n\r\"'.-+eE0123456789 :TZ#[]{}=()/\\$", "\x00", "é", "°", "nan", "inf"]
TOKENS = st.one_of(st.sampled_from(SYNTAX), st.text(max_size=4))


@st.composite
def mutated(draw: st.DrawFn, text: str, tokens: st.SearchStrategy[str] = TOKENS) -> str:
    """``text`` after 1 to 6 random edits: insert, delete, replace, cut, repeat or drop lines."""
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["insert", "delete", "replace", "cut", "line", "drop"]))
        at = draw(st.integers(0, len(text)))
        if kind == "insert":
            text = text[:at] + draw(tokens) + text[at:]
        elif kind == "delete":
            text = text[:at] + text[at + draw(st.integers(1, 20)) :]
        elif kind == "replace":
            text = text[:at] + draw(tokens) + text[at + 1 :]
        elif kind == "cut":
            text = text[:at]
        else:
            lines = text.splitlines(keepends=True) or [""]
            i = draw(st.integers(0, len(lines) - 1))
            lines[i : i + 1] = [lines[i]] * (2 if kind == "line" else 0)
            text = "".join(lines)
    return text


def _only_bayescal_errors(call: Any) -> None:
    """Run ``call``; success and BayescalError are fine, anything else fails the test."""
    try:
        call()
    except BayescalError as exc:
        message = exc.one_line()
    else:
        return
    assert "\n" not in message


# --------------------------------------------------------------------------- readers


@FUZZ
@given(data=st.binary(max_size=2000))
def test_csv_reader_on_random_bytes(data: bytes, tmp_path: Path) -> None:
    path = tmp_path / "x.csv"
    path.write_bytes(data)
    _only_bayescal_errors(lambda: read_csv(path, "time"))


@FUZZ
@given(text=mutated(SMALL_CSV), delimiter=st.sampled_from([",", ";"]))
def test_csv_reader_on_mangled_files(text: str, delimiter: str, tmp_path: Path) -> None:
    path = tmp_path / "x.csv"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    _only_bayescal_errors(
        lambda: read_csv(path, "time", time_zone="UTC-06:00", delimiter=delimiter)
    )


def _valid_parquet() -> bytes:
    frame = pd.read_csv(io.StringIO(SMALL_CSV))
    frame["time"] = pd.to_datetime(frame["time"])
    buffer = io.BytesIO()
    frame.to_parquet(buffer, index=False)
    return buffer.getvalue()


PARQUET = _valid_parquet()


@st.composite
def mangled_bytes(draw: st.DrawFn, data: bytes) -> bytes:
    """``data`` with 1 to 8 bytes overwritten, or cut short."""
    out = bytearray(data)
    if draw(st.booleans()):
        return bytes(out[: draw(st.integers(0, len(out)))])
    for _ in range(draw(st.integers(1, 8))):
        out[draw(st.integers(0, len(out) - 1))] = draw(st.integers(0, 255))
    return bytes(out)


@FUZZ
@given(data=st.one_of(st.binary(max_size=2000), mangled_bytes(PARQUET)))
def test_parquet_reader_on_random_and_mangled_bytes(data: bytes, tmp_path: Path) -> None:
    path = tmp_path / "x.parquet"
    path.write_bytes(data)
    _only_bayescal_errors(lambda: read_parquet(path, "time"))


@FUZZ
@given(
    data=st.one_of(st.binary(max_size=2000).map(lambda b: b.decode("latin-1")), mutated(SMALL_EPW))
)
def test_epw_reader_on_random_and_mangled_files(data: str, tmp_path: Path) -> None:
    path = tmp_path / "x.epw"
    path.write_text(data, encoding="utf-8", errors="surrogatepass")
    _only_bayescal_errors(lambda: read_epw(path))


@FUZZ
@given(
    data=st.one_of(
        st.binary(max_size=2000).map(lambda b: b.decode("latin-1")), mutated(SMALL_MODELICA)
    ),
    table=st.sampled_from([None, "tab", "other"]),
)
def test_modelica_reader_on_random_and_mangled_files(
    data: str, table: str | None, tmp_path: Path
) -> None:
    path = tmp_path / "x.txt"
    path.write_text(data, encoding="utf-8", errors="surrogatepass")
    epoch = datetime(2013, 1, 1)
    _only_bayescal_errors(lambda: read_modelica_table(path, epoch, table=table))


def test_unmangled_inputs_read(tmp_path: Path) -> None:
    """The seeds of the mutations are valid, so the properties exercise real parsing."""
    for name, text in (("x.epw", SMALL_EPW), ("x.txt", SMALL_MODELICA), ("x.csv", SMALL_CSV)):
        (tmp_path / name).write_text(text, encoding="utf-8")
    (tmp_path / "x.parquet").write_bytes(PARQUET)
    assert len(read_epw(tmp_path / "x.epw")) == 48
    assert len(read_modelica_table(tmp_path / "x.txt", datetime(2013, 1, 1))) == 24
    assert len(read_csv(tmp_path / "x.csv", "time")) == 59
    assert len(read_parquet(tmp_path / "x.parquet", "time")) == 59


# --------------------------------------------------------------------------- the whole study


@FUZZ
@given(text=mutated(WALL_CSV))
def test_validate_on_mangled_data(text: str, tmp_path: Path) -> None:
    """Reading, converting and aligning a mangled record: only bayescal errors."""
    (tmp_path / "data").mkdir(exist_ok=True)
    (tmp_path / "data" / "wall.csv").write_text(text, encoding="utf-8", errors="surrogatepass")
    (tmp_path / "study.toml").write_text(WALL_TOML, encoding="utf-8")
    _only_bayescal_errors(lambda: load_measured(load_study(tmp_path)))


KEYS = sorted({line.split("=")[0].strip() for line in WALL_TOML.splitlines() if "=" in line})
TOML_TOKENS = st.one_of(
    TOKENS,
    st.sampled_from(KEYS),
    st.sampled_from(['"', "'''", "[[", "]]", "[data]", "= ", "\n[x]\n", "true", "1e999"]),
    st.sampled_from(["inf", "-inf", "nan", "0", "-1", "2013-01-01T00:00:00", "{}", "[]"]),
)


@FUZZ
@given(text=mutated(WALL_TOML, TOML_TOKENS))
def test_study_loader_on_mangled_text(text: str, tmp_path: Path) -> None:
    (tmp_path / "study.toml").write_text(text, encoding="utf-8", errors="surrogatepass")
    _only_bayescal_errors(lambda: load_study(tmp_path))


VALUES = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(2**70), 2**70),
        st.floats(),
        st.text(max_size=20),
        st.datetimes(),
        st.sampled_from(["30min", "1D", "-1h", "degC", "W/m2", "../x.csv", "/etc/passwd"]),
        st.sampled_from(["Europe", "UTC+14:00", "9999-01-01", "0001-01-01T00:00:00", "K"]),
        st.sampled_from([0, 1, 2, 10**6, 2**63 - 1, 0.0, -0.0, 1e-300, 1e300]),
    ),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=12), inner, max_size=4)
    ),
    max_leaves=8,
)


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key path of a nested dict/list that does not lead to a table."""
    out = [prefix] if prefix and not isinstance(node, dict) else []
    if isinstance(node, dict):
        for key, value in node.items():
            out += _paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            out += _paths(value, (*prefix, i))
    return out


WALL_DICT = tomllib.loads(WALL_TOML)
WALL_PATHS = _paths(WALL_DICT)


def _leaves(node: Any) -> list[Any]:
    if isinstance(node, dict):
        return [leaf for value in node.values() for leaf in _leaves(value)]
    if isinstance(node, list):
        return [leaf for value in node for leaf in _leaves(value)]
    return [node]


# Strings of the study itself and other valid settings: a change to one of them often
# keeps the study valid, so that the data are then loaded with the changed settings.
PLAUSIBLE_TEXT = [
    *sorted({v for v in _leaves(WALL_DICT) if isinstance(v, str)}),
    *["15min", "1h", "2D", "0min", "UTC", "UTC+01:00", "Europe/Brussels", "degF", "K"],
    *["kW/m2", "2013-01-20T00:00:00", "2013-02-10T00:00:00", "beta"],
]
FACTORS = [0.0, 0.5, 0.99, 1.01, 2.0, -1.0, 1e3, 1e-3]


def _plausible(draw: st.DrawFn, old: Any) -> Any:
    """A value like ``old``: a scaled number, another valid string, or anything at all."""
    if isinstance(old, bool) or not isinstance(old, int | float | str):
        return draw(VALUES)
    if isinstance(old, str):
        return draw(st.sampled_from(PLAUSIBLE_TEXT))
    value = old * draw(st.sampled_from(FACTORS))
    return round(value) if isinstance(old, int) else value


@st.composite
def changed_study(draw: st.DrawFn) -> dict[str, Any]:
    """The wall study's parsed content with 1 to 3 values changed, keys removed or added."""
    raw = copy.deepcopy(WALL_DICT)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(WALL_PATHS))
        parent: Any = raw
        try:
            for part in path[:-1]:
                parent = parent[part]
            kind = draw(st.sampled_from(["like", "like", "like", "set", "remove", "add"]))
            if kind == "like":
                parent[path[-1]] = _plausible(draw, parent[path[-1]])
            elif kind == "set":
                parent[path[-1]] = draw(VALUES)
            elif kind == "remove" and isinstance(parent, dict):
                parent.pop(path[-1], None)
            elif isinstance(parent, dict):
                parent[draw(st.text(min_size=1, max_size=12))] = draw(VALUES)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier change removed or replaced this path
    return raw


@pytest.fixture(scope="module")
def wall_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A study folder holding the wall example's data (read-only for the tests)."""
    folder = tmp_path_factory.mktemp("wall")
    (folder / "data").mkdir()
    (folder / "data" / "wall.csv").write_text(WALL_CSV, encoding="utf-8")
    return folder


@FUZZ
@given(raw=changed_study())
def test_study_validation_on_changed_content(raw: dict[str, Any], wall_folder: Path) -> None:
    """Changed settings fail validation, or the data load with them (or fail to, clearly)."""
    _only_bayescal_errors(lambda: load_measured(study_from_dict(raw, root=wall_folder)))


@FUZZ
@given(raw=st.dictionaries(st.text(max_size=10), VALUES, max_size=8))
def test_study_validation_on_random_documents(raw: dict[str, Any], tmp_path: Path) -> None:
    _only_bayescal_errors(lambda: study_from_dict(raw, root=tmp_path))


def test_unchanged_study_is_valid(tmp_path: Path) -> None:
    """The seed of the study mutations validates, so failures come from the changes."""
    study = study_from_dict(copy.deepcopy(WALL_DICT), root=tmp_path)
    assert set(study.parameters) == {"k_cb", "cp_cb", "cp_fb"}


@pytest.mark.parametrize("text", ["", "\x00", "[data\n", "a = 1\na = 2\n", "x = 1e999999"])
def test_study_loader_on_small_broken_texts(text: str, tmp_path: Path) -> None:
    (tmp_path / "study.toml").write_text(text, encoding="utf-8")
    with pytest.raises(BayescalError):
        load_study(tmp_path)
