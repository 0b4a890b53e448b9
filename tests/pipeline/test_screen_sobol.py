"""``bayescal screen`` with ``[screening] method = "sobol"`` on the fixture wall: the same top
parameters as Morris, its files and page, and its keys' one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import load_study
from bayescal.errors import ConfigError
from bayescal.pipeline.screen import screen
from screen_study import SERIAL, screen_study

pytest.importorskip("SALib", reason="screening needs SALib")


def test_sobol_proposes_what_morris_proposes(tmp_path: Path) -> None:
    sobol_dir = screen_study(tmp_path, 'method = "sobol"\nruns = 30\npaths = 20\nsaltelli = 512\n'
                             "bootstrap = 100\nthreshold = 0.05\n")  # fmt: skip
    res = screen(load_study(sobol_dir), options=SERIAL)
    assert res.method == "sobol"
    assert res.design.runs == 30
    assert res.runs.n_failed == 0
    folder = sobol_dir / "out" / "screening"
    for name in ("screening.html", "sobol.csv", "proposal.json", "design.csv"):
        assert (folder / name).is_file(), name
    assert not (folder / "morris.csv").exists()
    table = pd.read_csv(folder / "sobol.csv")
    assert len(table) == 5
    assert table["q2"].iloc[0] > 0.9  # the steady flux is smooth in the parameters
    top = set(table.sort_values("rank")["parameter"].iloc[:2])
    # the conductivities set the steady flux: the boards (R = 1.7 m²·K/W) and the concrete (1.25)
    assert top == {"k_fb", "k_cb"}
    assert table.set_index("parameter").loc["d_fb", "normalised"] < 0.05
    assert "d_fb" not in res.proposal.selected
    document = json.loads((folder / "proposal.json").read_text(encoding="utf-8"))
    assert document["method"] == "sobol"
    assert document["measure"] == "ST"
    page = (folder / "screening.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == 1
    assert "Sobol" in page
    # Morris on the same study proposes the same parameters, most influential first
    morris_dir = screen_study(
        tmp_path, "trajectories = 4\nbootstrap = 100\nthreshold = 0.05\n", "m"
    )
    morris = screen(load_study(morris_dir), options=SERIAL)
    assert set(morris.proposal.selected[:2]) == top
    assert set(morris.proposal.selected) == set(res.proposal.selected)
    # a second screen runs nothing: every run is in the cache
    assert screen(load_study(sobol_dir), options=SERIAL).runs.n_cached == 30


def test_sobol_command_prints_the_indices(tmp_path: Path) -> None:
    study = screen_study(tmp_path, 'method = "sobol"\nruns = 20\npaths = 5\nsaltelli = 256\n')
    result = CliRunner().invoke(main, ["screen", str(study), "--backend", "serial"])
    assert result.exit_code == 0, result.output
    assert "Sobol ST and S1 [95 %]" in result.output
    assert "proposed (ST >= 0.1 × the largest" in result.output


@pytest.mark.parametrize(
    ("section", "match"),
    [
        ('method = "sobol"\ntrajectories = 5\n', r"screening\.trajectories: only applies to "
         r"method = 'morris' \(method is 'sobol'\)"),
        ("runs = 50\n", r"screening\.runs: only applies to method = 'sobol'"),
        ('method = "sobol"\nsaltelli = 1000\n', r"saltelli must be a power of 2.*try 512 or 1024"),
        ('method = "sobel"\n', r"screening\.method"),
        ('method = "sobol"\npaths = -1\n', r"screening\.paths"),
    ],
)  # fmt: skip
def test_bad_keys_are_one_line(tmp_path: Path, section: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        load_study(screen_study(tmp_path, section))
    assert "\n" not in str(info.value)


def test_too_few_runs_is_one_line(tmp_path: Path) -> None:
    study = load_study(screen_study(tmp_path, 'method = "sobol"\nruns = 5\n'))
    with pytest.raises(ConfigError, match=r"screening\.runs = 5 is too few for 5 parameters: "
                       r"the Sobol method's GP needs at least 7") as info:  # fmt: skip
        screen(study, options=SERIAL)
    assert "\n" not in str(info.value)


def test_the_budget_counts_the_hypercube(tmp_path: Path) -> None:
    from bayescal.data.measured import load_measured
    from bayescal.pipeline.budget import screening_need

    study = load_study(screen_study(tmp_path, 'method = "sobol"\n'))
    need = screening_need(study, load_measured(study))
    assert need.key == "screening.runs"
    assert need.detail.startswith("50 runs (Sobol's Latin hypercube)")  # 10 × 5 parameters
