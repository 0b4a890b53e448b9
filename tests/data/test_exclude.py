"""``[[data.exclude]]``: windows of the file whose samples are not measurements."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayescal.cli.progress import study_summary
from bayescal.config import load_study
from bayescal.data import load_measured
from bayescal.errors import ConfigError, DataError
from bayescal.examples import copy_example

#: A training-day instant of the wall example (local time, UTC-6) and its spike. [W/m²]
SPIKE_AT = pd.Timestamp("2013-01-16 06:00")
SPIKE = -18.0


def _wall(tmp_path: Path, exclude: str = "", extra: str = "") -> Path:
    """The wall example with ``exclude`` (TOML of ``[[data.exclude]]`` tables) and
    ``extra`` ``[data]`` keys added."""
    folder = tmp_path / "wall"
    if not folder.exists():
        copy_example("wall", folder)
        (folder / "study.orig").write_text((folder / "study.toml").read_text(encoding="utf-8"))
    text = (folder / "study.orig").read_text(encoding="utf-8")
    text = text.replace('step = "30min"\n', f'step = "30min"\n{extra}\n', 1) + "\n" + exclude
    (folder / "study.toml").write_text(text, encoding="utf-8")
    return folder


def _ten_minutes(folder: Path, spike: bool) -> pd.DataFrame:
    """Replace the example's half-hourly file by 10-minute samples that average back to it
    (each value at t - 10 min, t and t + 10 min), with one spiked sample if asked."""
    half = pd.read_csv(folder / "data" / "wall.csv", parse_dates=["time"])
    fine = pd.concat(
        [half.assign(time=half["time"] + pd.Timedelta(minutes=d)) for d in (-10, 0, 10)]
    ).sort_values("time", kind="stable")
    if spike:
        fine.loc[fine["time"] == SPIKE_AT + pd.Timedelta(minutes=10), "q_si"] += SPIKE
    fine["time"] = fine["time"].dt.strftime("%Y-%m-%d %H:%M")
    fine.to_csv(folder / "data" / "wall.csv", index=False)
    return half


def _at(measured: object, when: pd.Timestamp) -> int:
    utc = (when + pd.Timedelta(hours=6)).to_datetime64()
    return int(np.flatnonzero(measured.times == utc)[0])  # type: ignore[attr-defined]


WINDOW = """[[data.exclude]]
start = "2013-01-16T06:05:00"
end = "2013-01-16T06:15:00"
columns = ["heat_flux_in"]
reason = "sun patch on the plate"
"""


def test_an_excluded_sample_leaves_the_mean_of_the_others(tmp_path: Path) -> None:
    folder = _wall(tmp_path)
    half = _ten_minutes(folder, spike=True)
    truth = half.set_index("time")["q_si"]
    spiked = load_measured(load_study(folder))
    i = _at(spiked, SPIKE_AT)
    # the spike enters the half-hour's centred mean with a third of its size
    assert spiked.outputs["heat_flux_in"][i] == pytest.approx(truth[SPIKE_AT] + SPIKE / 3, abs=1e-9)
    folder = _wall(tmp_path, WINDOW)
    clean = load_measured(load_study(folder))
    # excluded, the half-hour is the mean of its two other samples: the original value
    assert clean.outputs["heat_flux_in"][i] == pytest.approx(truth[SPIKE_AT], abs=1e-9)
    others = np.arange(clean.n) != i
    np.testing.assert_array_equal(
        clean.outputs["heat_flux_in"][others], spiked.outputs["heat_flux_in"][others]
    )
    # the boundary conditions keep every sample, and no period is lost
    for name in clean.forcing.series:
        np.testing.assert_array_equal(clean.forcing.series[name], spiked.forcing.series[name])
    assert clean.layout.m_star == spiked.layout.m_star
    assert not clean.gaps
    (window,) = clean.excluded
    assert window.values == 1
    assert window.columns == ("heat_flux_in",)
    summary = study_summary(load_study(folder), clean)
    assert "excluded (data.exclude): 1 window(s)" in summary
    assert "2013-01-16 06:05 to 06:15 local: 1 value(s) of heat_flux_in (sun patch" in summary


def test_an_excluded_sample_on_the_clock_is_a_gap(tmp_path: Path) -> None:
    window = WINDOW.replace("06:05:00", "06:00:00").replace("06:15:00", "06:30:00")
    base = load_measured(load_study(_wall(tmp_path)))
    dropped = load_measured(load_study(_wall(tmp_path, window)))
    # a gap in a measurement drops the period it falls in
    assert dropped.layout.m_star == base.layout.m_star - 1
    assert dropped.layout.dropped_starts.size == base.layout.dropped_starts.size + 1
    (gap,) = dropped.gaps
    assert gap.columns == ("heat_flux_in",)
    assert gap.samples == 1
    # interpolated where the study allows it: the period is kept
    filled = load_measured(load_study(_wall(tmp_path, window, 'max_gap_interpolate = "1h"')))
    assert filled.layout.m_star == base.layout.m_star
    i = _at(filled, pd.Timestamp("2013-01-16 06:00"))
    q = base.outputs["heat_flux_in"]
    assert filled.outputs["heat_flux_in"][i] == pytest.approx(0.5 * (q[i - 1] + q[i + 1]))


def test_every_column_when_none_is_named(tmp_path: Path) -> None:
    window = "[[data.exclude]]\nstart = 2013-01-16T06:00:00\nend = 2013-01-16T06:30:00\n"
    measured = load_measured(load_study(_wall(tmp_path, window, 'max_gap_interpolate = "1h"')))
    (applied,) = measured.excluded
    assert set(applied.columns) == {"temp_surf_out", "temp_surf_in", "heat_flux_in"}
    assert applied.values == 3


@pytest.mark.parametrize(
    ("window", "message"),
    [
        (
            '[[data.exclude]]\nstart = "2013-01-16T07:00:00"\nend = "2013-01-16T06:00:00"\n',
            "data.exclude[0].end: 2013-01-16 06:00:00 is not after its start",
        ),
        (
            '[[data.exclude]]\nstart = "2013-01-16T06:00:00"\nend = "2013-01-16T07:00:00"\n'
            'columns = ["heat_flux"]\n',
            "data.exclude[0].columns: 'heat_flux' is not a column of [data.columns]; "
            "did you mean 'heat_flux_in'?",
        ),
    ],
)
def test_impossible_windows_are_refused_with_their_key(
    tmp_path: Path, window: str, message: str
) -> None:
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_study(_wall(tmp_path, window))


def test_a_window_outside_the_file_names_the_files_span(tmp_path: Path) -> None:
    window = '[[data.exclude]]\nstart = "2014-01-16T06:00:00"\nend = "2014-01-16T07:00:00"\n'
    with pytest.raises(DataError, match=r"data.exclude\[0\]: no row of the file") as info:
        load_measured(load_study(_wall(tmp_path, window)))
    assert "the file runs from 2013-01-12 00:00" in str(info.value.hint)
