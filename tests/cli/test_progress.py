"""Progress bars on the terminal (bayescal.cli.progress)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sims_for_tests as sims
from bayescal.cli.progress import simulation_bar
from bayescal.design import UniformPrior, latin_hypercube
from bayescal.runner import run_design
from bayescal.simulators.base import Forcing

N = 48
FORCING = Forcing(3600.0, {"temp_air_out": 10.0 + 5.0 * np.sin(np.arange(N) / 3.0)})
# 10 runs of a Latin hypercube: exactly one has a in [0.9, 1), which Failing breaks.
DESIGN = latin_hypercube({"a": UniformPrior(0.0, 1.0), "b": UniformPrior(-1.0, 1.0)}, 10, seed=1)


def test_simulation_bar_counts_runs_and_failures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    progress, close = simulation_bar(10, desc="runs")
    results = run_design(
        sims.Failing(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial", progress=progress
    )
    close()
    err = capsys.readouterr().err
    assert results.n_failed == 1
    assert "runs: 100%" in err
    assert "failed=1" in err


def test_comparison_table_keeps_long_variant_names_apart() -> None:
    import pandas as pd

    from bayescal.cli.progress import comparison_text

    names = ["box-coheating-white", "box-coheating-white-delta"]
    table = pd.DataFrame(
        {
            "rank": [1, 2],
            "variant": names,
            "elpd": [-10.0, -20.0],
            "se": [1.0, 1.0],
            "elpd_diff": [0.0, 10.0],
            "se_diff": [0.0, 2.0],
            "p_loo": [3.0, 4.0],
            "k_high": [0, 0],
            "refits": [0, 0],
            "periods": [11, 11],
        }
    )
    rows = comparison_text(table, [], {}).splitlines()[2:4]
    assert rows[0].split()[1] == names[0]
    assert rows[1].split()[1] == names[1]
