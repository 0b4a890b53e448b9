"""Tests of the external-command simulator adapter with real external programs."""

from __future__ import annotations

import json
import os
import pickle
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bayescal.errors import ConfigError, SimulatorError
from bayescal.simulators.base import Forcing, Simulator
from bayescal.simulators.command import CommandFailed, CommandSimulator
from paths import PROGRAMS
from rc_reference import rc_numerical

STEP = 600.0  # [s]
TEMPLATE = "R = $R\nC = ${C}\nT0 = $T0\n# a literal dollar: $$5\n"


@pytest.fixture
def forcing() -> Forcing:
    rng = np.random.default_rng(20240601)
    t = np.arange(145) * STEP
    u = 5.0 + 8.0 * np.sin(2 * np.pi * t / 86400.0) + rng.normal(0.0, 1.0, t.size)
    return Forcing(step=STEP, series={"temp_air_out": u}, start=np.datetime64("2024-03-01T00:00"))


@pytest.fixture
def study(tmp_path: Path) -> Path:
    base = tmp_path / "study"
    base.mkdir()
    (base / "params.tmpl").write_text(TEMPLATE, encoding="utf-8")
    return base


def runs_dir(study: Path) -> Path:
    """Run folders go beside the study, inside pytest's tmp_path (kept ones included)."""
    path = study.parent / "runs"
    path.mkdir(exist_ok=True)
    return path


def rc_wall(study: Path, **kw) -> CommandSimulator:
    options = {
        "base_dir": study,
        "parameters": ["R", "C", "T0"],
        "templates": {"params.tmpl": "params.txt"},
        "inputs": ["temp_air_out"],
        "outputs": {"heat_flux_out": "q", "temp_node": "T"},
        "time_column": "time",
        "timeout": 60.0,
        "work_dir": runs_dir(study),
    }
    options.update(kw)
    command = options.pop("command", [sys.executable, str(PROGRAMS / "rc_wall.py")])
    return CommandSimulator(command, **options)


def tool(study: Path, mode: str, *args: str, **kw) -> CommandSimulator:
    options = {
        "base_dir": study,
        "parameters": ["R"],
        "templates": {"params.tmpl": "params.txt"},
        "nominal": {"R": 1.0, "C": 1.0, "T0": 0.0},
        "outputs": {"y": "y"},
        "timeout": 60.0,
        "work_dir": runs_dir(study),
    }
    options.update(kw)
    if options["parameters"] == ["R"]:
        (study / "params.tmpl").write_text("R = $R\n", encoding="utf-8")
        options["nominal"] = {"R": 1.0}
    return CommandSimulator([sys.executable, str(PROGRAMS / "tool.py"), mode, *args], **options)


def reference(u: np.ndarray, r: float, c: float, t0: float) -> tuple[np.ndarray, np.ndarray]:
    return rc_numerical(u, STEP, r, c, t0)


def alive(pid: int) -> bool:
    """Whether a process exists and is not a zombie (Linux /proc, else signal 0)."""
    stat = Path(f"/proc/{pid}/stat")
    if Path("/proc").is_dir():
        try:
            return stat.read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except (FileNotFoundError, ProcessLookupError):
            return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


# -- results ---------------------------------------------------------------------------


def test_python_program_matches_reference(study: Path, forcing: Forcing) -> None:
    sim = rc_wall(study)
    assert isinstance(sim, Simulator)
    out = sim.simulate({"R": 0.5, "C": 2.0e4, "T0": 20.0}, forcing)
    temp, q = reference(forcing["temp_air_out"], 0.5, 2.0e4, 20.0)
    # The program solves the ODE exactly and writes 17 digits; the DOP853 reference is
    # accurate to ~1e-11 K per step, ~1e-9 K over 144 steps: 1e-8 K (2e-8 W/m² with
    # R = 0.5) bounds both.
    np.testing.assert_allclose(out["temp_node"], temp, rtol=0, atol=1e-8)
    np.testing.assert_allclose(out["heat_flux_out"], q, rtol=0, atol=2e-8)
    assert set(out) == {"heat_flux_out", "temp_node"}
    assert out["heat_flux_out"].shape == (forcing.n,)


def test_parameters_take_effect(study: Path, forcing: Forcing) -> None:
    sim = rc_wall(study)
    base = sim.simulate({"R": 0.5, "C": 2.0e4, "T0": 20.0}, forcing)
    other = sim.simulate({"R": 1.3, "C": 7.0e4, "T0": 15.0}, forcing)
    _, q = reference(forcing["temp_air_out"], 1.3, 7.0e4, 15.0)
    np.testing.assert_allclose(other["heat_flux_out"], q, rtol=0, atol=2e-8)  # as above
    assert np.max(np.abs(other["heat_flux_out"] - base["heat_flux_out"])) > 1.0


def test_nominal_values_fill_missing_parameters(study: Path, forcing: Forcing) -> None:
    sim = rc_wall(study, nominal={"C": 2.0e4, "T0": 20.0})
    out = sim.simulate({"R": 0.5}, forcing)
    _, q = reference(forcing["temp_air_out"], 0.5, 2.0e4, 20.0)
    np.testing.assert_allclose(out["heat_flux_out"], q, rtol=0, atol=2e-8)  # as above
    with pytest.raises(SimulatorError, match=r"no value for parameter\(s\) \['C', 'T0'\]"):
        rc_wall(study).simulate({"R": 0.5}, forcing)


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
def test_compiled_c_program(study: Path, forcing: Forcing) -> None:
    (study / "bin").mkdir()
    subprocess.run(
        ["gcc", "-O2", "-o", str(study / "bin" / "rc_wall"), str(PROGRAMS / "rc_wall.c"), "-lm"],
        check=True,
    )
    sim = rc_wall(study, command=["bin/rc_wall"])  # relative to the study folder
    out = sim.simulate({"R": 0.8, "C": 3.0e4, "T0": 18.0}, forcing)
    temp, q = reference(forcing["temp_air_out"], 0.8, 3.0e4, 18.0)
    np.testing.assert_allclose(out["temp_node"], temp, rtol=0, atol=1e-8)  # as above
    np.testing.assert_allclose(out["heat_flux_out"], q, rtol=0, atol=2e-8)


def test_pickled_simulator_runs_the_same(study: Path, forcing: Forcing) -> None:
    sim = rc_wall(study)
    copy = pickle.loads(pickle.dumps(sim))
    theta = {"R": 0.5, "C": 2.0e4, "T0": 20.0}
    a, b = sim.simulate(theta, forcing), copy.simulate(theta, forcing)
    np.testing.assert_array_equal(a["heat_flux_out"], b["heat_flux_out"])  # deterministic


def test_successful_run_folder_is_removed(study: Path, forcing: Forcing, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    runs.mkdir()
    rc_wall(study, work_dir=runs).simulate({"R": 0.5, "C": 2.0e4, "T0": 20.0}, forcing)
    assert list(runs.iterdir()) == []


def test_placeholders_and_env(study: Path, forcing: Forcing, tmp_path: Path) -> None:
    record = tmp_path / "record.json"
    args = ["{forcing_csv}", "{params.txt}", "{n}", "{step}", "{start}", "x{run_dir}x", "{0}"]
    sim = tool(study, "record", str(record), *args, env={"BAYESCAL_TEST_VAR": "42"})
    sim.simulate({"R": 2.5}, forcing)
    got = json.loads(record.read_text())
    run_dir = Path(got["argv"][0]).parent
    assert got["argv"][0] == str(run_dir / "forcing.csv")
    assert got["argv"][1:5] == [str(run_dir / "params.txt"), "145", "600.0", "2024-03-01T00:00:00"]
    assert got["argv"][5:] == [f"x{run_dir}x", "{0}"]  # not identifier-like: left alone
    assert {"forcing.csv", "params.txt"} <= set(got["files"])
    assert got["env"] == "42"


def test_forcing_csv_content(study: Path, forcing: Forcing, tmp_path: Path) -> None:
    copy = tmp_path / "copy.csv"
    sim = CommandSimulator(
        [
            sys.executable,
            "-c",
            f"import shutil; shutil.copy('forcing.csv', {str(copy)!r}); "
            "open('out.csv', 'w').write('y\\n' + '1\\n' * 145)",
        ],
        base_dir=study,
        parameters=[],
        inputs=["temp_air_out"],
        outputs={"y": "y"},
    )
    sim.simulate({}, forcing)
    data = np.loadtxt(copy, delimiter=",", skiprows=1)
    assert copy.read_text().splitlines()[0] == "time,temp_air_out"
    np.testing.assert_array_equal(data[:, 0], np.arange(145) * STEP)
    np.testing.assert_array_equal(data[:, 1], forcing["temp_air_out"])  # %.17g round-trips


# -- failures --------------------------------------------------------------------------


def test_nonzero_exit_keeps_stderr_and_run_folder(study: Path, forcing: Forcing) -> None:
    sim = tool(study, "fail")
    with pytest.raises(CommandFailed, match=r"exited with code 3.*R is negative") as info:
        sim.simulate({"R": 1.0}, forcing)
    err = info.value
    assert err.exit_code == 3
    assert "parameter R is negative" in err.stderr
    assert err.command[0] == sys.executable
    assert err.command[-1] == "fail"
    assert err.run_dir is not None
    assert (Path(err.run_dir) / "params.txt").is_file()
    assert "\n" not in str(err)
    shutil.rmtree(err.run_dir)


def test_timeout_kills_program_and_its_child(study: Path, forcing: Forcing, tmp_path: Path) -> None:
    pidfile = tmp_path / "pids.txt"
    sim = tool(study, "sleep", "30", str(pidfile), timeout=1.0)
    start = time.monotonic()
    with pytest.raises(CommandFailed, match=r"timed out after 1 s") as info:
        sim.simulate({"R": 1.0}, forcing)
    elapsed = time.monotonic() - start
    # 1 s limit + interpreter start-up, writing files and reaping: 2 s is ample on a
    # loaded 2-core CI machine, and far below the 30 s the program wanted to sleep.
    assert elapsed < 3.0
    assert info.value.exit_code is not None
    assert info.value.exit_code < 0
    pids = [int(p) for p in pidfile.read_text().split()]
    deadline = time.monotonic() + 5.0  # the orphaned child is reaped by init, not by us
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(p) for p in pids)
    shutil.rmtree(info.value.run_dir)


@pytest.mark.parametrize(
    ("mode", "message"),
    [
        ("nooutput", "wrote no output file 'out.csv'"),
        ("garbage", "is malformed"),
        ("nan", r"column 'y' of 'out.csv' has a NaN or infinite value \(first at row 144\)"),
        ("short", "has 144 rows, the forcing has 145 samples"),
        ("offclock", r"off the forcing clock: row 1 has 601.0 s, expected 600.0 s"),
    ],
)
def test_bad_output_files(study: Path, forcing: Forcing, mode: str, message: str) -> None:
    sim = tool(study, mode, time_column="time")
    with pytest.raises(CommandFailed, match=message) as info:
        sim.simulate({"R": 1.0}, forcing)
    assert info.value.exit_code == 0
    shutil.rmtree(info.value.run_dir)


def test_missing_output_column(study: Path, forcing: Forcing, tmp_path: Path) -> None:
    sim = tool(study, "record", str(tmp_path / "r.json"), outputs={"y": "flux"})
    with pytest.raises(
        CommandFailed, match=r"lacks column\(s\) \['flux'\]; it has \['time', 'y'\]"
    ):
        sim.simulate({"R": 1.0}, forcing)


def test_missing_forcing_series(study: Path, forcing: Forcing) -> None:
    sim = rc_wall(study, inputs=["temp_air_out", "ghi"])
    with pytest.raises(SimulatorError, match=r"needs boundary condition\(s\) \['ghi'\]"):
        sim.simulate({"R": 0.5, "C": 2.0e4, "T0": 20.0}, forcing)


# -- safety ----------------------------------------------------------------------------


def injections(sentinel: Path, victim: Path) -> list[str]:
    return [
        f"; touch {sentinel}",
        f"$(touch {sentinel})",
        f"`touch {sentinel}`",
        f"| touch {sentinel}",
        f"&& touch {sentinel}",
        f"; rm -rf {victim}",
        "../../etc/passwd",
    ]


def test_shell_syntax_in_arguments_is_passed_literally(
    study: Path, forcing: Forcing, tmp_path: Path
) -> None:
    sentinel, victim = tmp_path / "pwned", tmp_path / "victim"
    victim.mkdir()
    record = tmp_path / "record.json"
    strings = injections(sentinel, victim)
    tool(study, "record", str(record), *strings).simulate({"R": 1.0}, forcing)
    assert json.loads(record.read_text())["argv"] == strings
    assert not sentinel.exists()
    assert victim.is_dir()


def test_shell_syntax_in_file_names_is_inert(
    study: Path, forcing: Forcing, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    record = tmp_path / "record.json"
    name = "$(touch pwned) `touch pwned2`;touch pwned3.txt"
    sim = tool(study, "record", str(record), f"{{{name}}}", templates={"params.tmpl": name})
    sim.simulate({"R": 1.0}, forcing)
    got = json.loads(record.read_text())
    assert name in got["files"]
    assert got["argv"][0].endswith("/" + name)
    assert not any(p.name.startswith("pwned") for p in tmp_path.rglob("*"))
    assert not any(f.startswith("pwned") for f in got["files"])


@pytest.mark.parametrize("value", ["; rm -rf /tmp/x", "$(touch pwned)", "`id`", None, True, "1.0"])
def test_parameter_values_must_be_numbers(
    study: Path, forcing: Forcing, tmp_path: Path, value: object
) -> None:
    record = tmp_path / "record.json"
    sim = tool(study, "record", str(record))
    with pytest.raises(SimulatorError, match="parameter 'R' must be a real number"):
        sim.simulate({"R": value}, forcing)  # type: ignore[dict-item]
    assert not record.exists()  # the program never ran


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_parameter_values_must_be_finite(study: Path, forcing: Forcing, value: float) -> None:
    with pytest.raises(SimulatorError, match="parameter 'R' is not finite"):
        tool(study, "record", "x").simulate({"R": value}, forcing)


def test_unknown_parameter_is_rejected(study: Path, forcing: Forcing) -> None:
    with pytest.raises(SimulatorError, match=r"has no parameter\(s\) \['K'\]"):
        tool(study, "record", "x").simulate({"K": 1.0}, forcing)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"templates": {"params.tmpl": "../../etc/passwd"}}, "must be a relative path"),
        ({"templates": {"params.tmpl": "/etc/passwd"}}, "must be a relative path"),
        ({"templates": {"params.tmpl": "sub/../../x"}}, "must be a relative path"),
        ({"templates": {"../outside.tmpl": "p.txt"}}, "points outside the study folder"),
        ({"templates": {"params.tmpl": "forcing.csv"}}, "is reserved"),
        ({"output_file": "../../out.csv"}, "must be a relative path"),
        ({"command": ["../bin/model"]}, "points outside the study folder"),
        ({"command": ["./no-such-model"]}, "not found"),
        ({"command": ["no-such-program-bayescal"]}, "is not on the PATH"),
        ({"command": "python model.py; rm -rf /"}, "must be a non-empty list of strings"),
        ({"command": [sys.executable, "{forcing_csv.__class__}"]}, "unknown placeholder"),
        ({"command": [sys.executable, "{input_dir}"]}, "unknown placeholder"),
        ({"parameters": ["R", "C", "T0", "os.system"]}, "is not a valid name"),
        ({"parameters": ["R", "C", "T0", "K"]}, r"\['K'\] appear in no template"),
        ({"parameters": ["R", "C"]}, r"placeholder\(s\) \['T0'\] that are not parameters"),
        ({"timeout": 0.0}, "timeout must be a positive"),
        ({"outputs": {}}, "at least one output"),
    ],
)
def test_bad_configuration_is_rejected(study: Path, change: dict, message: str) -> None:
    (study.parent / "outside.tmpl").write_text("R = $R\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=message):
        rc_wall(study, **change)


@pytest.mark.parametrize(
    "text", ["R = $(touch pwned)\n", "R = ${R.__class__}\n", "R = $R{0}\nx = ${R\n"]
)
def test_templates_cannot_hold_code(study: Path, text: str) -> None:
    (study / "params.tmpl").write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"not a placeholder such as \$R"):
        rc_wall(study, parameters=["R"])
