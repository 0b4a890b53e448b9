"""Nothing from a study file reaches a shell, and relative paths stay in the study folder.

Strings with shell syntax (``;``, ``$(...)``, backticks, ``|``, ``&&``, spaces,
newlines) are put into parameter names, column names, template files and
values, command arguments, environment values, file names and the study
folder itself. The promises checked:

* names that must be identifiers are refused with a one-line ConfigError;
* everything else is used literally: a command is an argument list run
  without a shell, so each string reaches the program as one argument,
  byte for byte, and no sentinel file is ever created;
* templates substitute ``$NAME`` with parameter values only (numbers): no
  expression, attribute or call can be written in one;
* a relative path (data, template, program, model, output folder) cannot
  leave the study folder; an absolute path is taken as given.

The injected commands only ever ``touch`` a sentinel file or remove a victim
folder inside pytest's temporary folder, so a regression fails the test
without harming the machine.
"""

from __future__ import annotations

import ast
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import build_simulator, load_study
from bayescal.data import load_measured
from bayescal.errors import ConfigError
from paths import REPO

WALL = REPO / "src" / "bayescal" / "examples" / "wall"
SENTINEL = "PWNED"
RECORD = [sys.executable, "{base_dir}/record.py", "{base_dir}/r.json"]

RECORDER = """\
import json, os, sys
n = sum(1 for line in open("forcing.csv") if line.strip()) - 1
record = {
    "argv": sys.argv[2:],
    "files": sorted(os.listdir(".")),
    "env": os.environ.get("INJECTED"),
    "params": open("params.txt", encoding="utf-8").read(),
}
with open(sys.argv[1], "w", encoding="utf-8") as f:
    json.dump(record, f)
with open("out.csv", "w", encoding="utf-8") as f:
    f.write("q\\n" + "".join(f"{-7.0 - 0.001 * i!r}\\n" for i in range(n)))
"""

COMMAND_SIMULATOR = """
[simulator]
type = "command"
command = {command}
templates = {templates}
inputs = ["temp_surf_out", "temp_surf_in"]
timeout = 60.0
env = {{ INJECTED = {env} }}

[simulator.outputs]
file = "out.csv"
columns = {{ heat_flux_in = "q" }}

[parameters.r_wall]
unit = "m2K/W"
nominal = 0.5
prior = {{ distribution = "uniform", lower = 0.3, upper = 0.8 }}
targets = ["R"]

[outputs]
calibrate = ["heat_flux_in"]

[periods]
length = "1D"
warmup = "3D"
test_samples = 300

[design]
runs = 6
"""


def injections(tmp_path: Path) -> list[str]:
    """Shell syntax that would create the sentinel or remove the victim if a shell ran it."""
    sentinel, victim = tmp_path / SENTINEL, tmp_path / "victim"
    return [
        f"; touch {sentinel}",
        f"$(touch {sentinel})",
        f"`touch {sentinel}`",
        f"| touch {sentinel}",
        f"&& touch {sentinel} &&",
        f"; rm -rf {victim}",
        "| cat /etc/passwd",
        "../../etc/passwd",
        "~/.ssh/id_rsa",
        "two words",
        "a\nnewline",
        "quote ' and \" and \\",
        "${__import__('os').system('touch " + str(sentinel) + "')}",
        "{__import__('os')}",
    ]


@pytest.fixture
def guarded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """Run from tmp_path; afterwards no sentinel exists and the victim folder survives."""
    (tmp_path / "victim").mkdir()
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    assert not [p for p in tmp_path.rglob(f"*{SENTINEL}*") if p.name.startswith(SENTINEL)]
    assert not (Path.home() / SENTINEL).exists()
    assert (tmp_path / "victim").is_dir()


def wall_copy(folder: Path) -> Path:
    shutil.copytree(WALL, folder, ignore=shutil.ignore_patterns("out", "README.md"))
    return folder


def command_study(folder: Path, command: list[str], env: str = "plain", **templates: str) -> Path:
    """The wall example's data driven through the recorder program as a command simulator."""
    wall_copy(folder)
    (folder / "record.py").write_text(RECORDER, encoding="utf-8")
    (folder / "params.tmpl").write_text("R = $R\n", encoding="utf-8")
    toml = (folder / "study.toml").read_text(encoding="utf-8")
    head = toml[: toml.index("\n[simulator]\n")]
    templates = templates or {"params.tmpl": "params.txt"}
    section = COMMAND_SIMULATOR.format(
        command=json.dumps(command),
        templates="{ "
        + ", ".join(f"{json.dumps(k)} = {json.dumps(v)}" for k, v in templates.items())
        + " }",
        env=json.dumps(env),
    )
    (folder / "study.toml").write_text(head + "\n" + section, encoding="utf-8")
    return folder


def cli(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args))
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, result.stdout, result.stderr


def replace_in_study(folder: Path, old: str, new: str) -> None:
    toml = (folder / "study.toml").read_text(encoding="utf-8")
    assert old in toml
    (folder / "study.toml").write_text(toml.replace(old, new), encoding="utf-8")


# --------------------------------------------------------------------------- names


def test_injected_parameter_names_are_refused(guarded: Path) -> None:
    folder = wall_copy(guarded / "study")
    for name in injections(guarded):
        key = json.dumps(name)  # a TOML basic string: quoted key, escapes as in JSON
        replace_in_study(folder, "[parameters.k_cb]", f"[parameters.{key}]")
        code, out, err = cli("validate", str(folder))
        assert code == 2
        assert out == ""
        assert err.count("\n") == 1
        assert "parameter names are identifiers" in err
        replace_in_study(folder, f"[parameters.{key}]", "[parameters.k_cb]")


def test_injected_column_names_are_read_literally(guarded: Path) -> None:
    """Source columns named with shell syntax are just names: the study validates."""
    folder = wall_copy(guarded / "study")
    names = [n for n in injections(guarded) if "\n" not in n][:3]
    table = pd.read_csv(folder / "data" / "wall.csv", dtype=str)
    table.columns = ["time", *names]
    table.to_csv(folder / "data" / "wall.csv", index=False)
    for old, new in zip(['"T_se"', '"T_si"', '"q_si"'], names, strict=True):
        replace_in_study(folder, f"source = {old}", f"source = {json.dumps(new)}")
    study = load_study(folder)
    assert [spec.source for spec in study.data.columns.values()] == names
    measured = load_measured(study)
    assert np.isfinite(measured.outputs["heat_flux_in"]).all()


@pytest.mark.parametrize("target", ["R; touch PWNED", "$(touch PWNED)", "R`id`", "os.system"])
def test_injected_template_targets_are_refused(guarded: Path, target: str) -> None:
    folder = command_study(guarded / "study", RECORD)
    replace_in_study(folder, 'targets = ["R"]', f"targets = [{json.dumps(target)}]")
    with pytest.raises(ConfigError, match="is not a template placeholder name"):
        load_study(folder)


# --------------------------------------------------------------------------- commands


def test_command_arguments_and_env_reach_the_program_literally(guarded: Path) -> None:
    """End to end through `bayescal simulate`: each string arrives as one argument."""
    strings = injections(guarded)
    record = guarded / "record.json"
    folder = command_study(
        guarded / "study $(touch PWNED) `x`; y",
        [sys.executable, "{base_dir}/record.py", str(record), *strings],
        env=strings[1],
    )
    code, _, err = cli("simulate", str(folder), "--out", str(guarded / "sim out"))
    assert code == 0, err
    got = json.loads(record.read_text(encoding="utf-8"))
    assert got["argv"] == strings
    assert got["env"] == strings[1]
    assert got["params"] == "R = 0.5\n"
    assert (guarded / "sim out" / "simulation.csv").is_file()


def test_template_files_with_shell_syntax_render_literally(guarded: Path) -> None:
    """Shell syntax in a template is text; only $NAME placeholders are replaced."""
    folder = command_study(guarded / "study", RECORD)
    text = "".join(f"# {s}\n" for s in injections(guarded) if "$" not in s) + "R = $R\ncost = $$5\n"
    (folder / "params.tmpl").write_text(text, encoding="utf-8")
    sim = build_simulator(load_study(folder))
    measured = load_measured(load_study(folder))
    sim.simulate({"r_wall": 0.625}, measured.forcing)
    got = json.loads((folder / "r.json").read_text(encoding="utf-8"))
    expected = text.replace("$R", repr(0.625)).replace("$$", "$")
    assert got["params"] == expected


def test_file_names_with_shell_syntax_are_inert(guarded: Path) -> None:
    """Template, rendered file and data file names holding shell syntax are plain names."""
    source, rendered = "$(touch PWNED) x.tmpl", "`touch PWNED`; y.txt"
    folder = command_study(
        guarded / "study",
        [*RECORD, f"{{{rendered}}}"],
        **{source: rendered},
    )
    (folder / "params.tmpl").rename(folder / source)
    (folder / "record.py").write_text(
        RECORDER.replace('"params.txt"', repr(rendered)), encoding="utf-8"
    )
    (folder / "data" / "wall.csv").rename(folder / "data" / "$(touch PWNED) ; w.csv")
    replace_in_study(folder, 'file = "data/wall.csv"', 'file = "data/$(touch PWNED) ; w.csv"')
    study = load_study(folder)
    build_simulator(study).simulate({"r_wall": 0.5}, load_measured(study).forcing)
    got = json.loads((folder / "r.json").read_text(encoding="utf-8"))
    assert rendered in got["files"]
    assert got["argv"][0].endswith("/" + rendered)


@pytest.mark.parametrize(
    ("template", "message"),
    [
        ("R = ${__import__('os').system('touch PWNED')}\n", r"not a placeholder such as \$R"),
        ("R = $(touch PWNED)\n", r"not a placeholder such as \$R"),
        ("R = ${R.__class__}\n", r"not a placeholder such as \$R"),
        ("R = $R\nx = $HOME\n", r"placeholder\(s\) \['HOME'\] that are not parameters"),
        ("R = {R}\n", r"\['R'\] appear in no template"),
    ],
)
def test_templates_substitute_values_only(guarded: Path, template: str, message: str) -> None:
    folder = command_study(guarded / "study", RECORD)
    (folder / "params.tmpl").write_text(template, encoding="utf-8")
    with pytest.raises(ConfigError, match=message):
        build_simulator(load_study(folder))


def test_attribute_placeholders_in_arguments_are_refused(guarded: Path) -> None:
    folder = command_study(guarded / "study", [*RECORD, "{base_dir.__class__}"])
    with pytest.raises(ConfigError, match="unknown placeholder"):
        build_simulator(load_study(folder))


def test_set_values_are_numbers_only(guarded: Path) -> None:
    folder = command_study(guarded / "study", RECORD)
    code, _, err = cli("simulate", str(folder), "--set", f"r_wall=0.5; touch {guarded}/PWNED")
    assert code == 2
    assert "--set expects NAME=VALUE with a number" in err
    assert not (folder / "r.json").exists()  # the program never ran


# --------------------------------------------------------------------------- paths


ESCAPES = ["../wall.csv", "data/../../wall.csv", "./../wall.csv", "~/../../wall.csv"]


@pytest.mark.parametrize("path", ESCAPES)
def test_relative_data_path_cannot_leave_the_study(guarded: Path, path: str) -> None:
    folder = wall_copy(guarded / "study")
    shutil.copy(folder / "data" / "wall.csv", guarded / "wall.csv")
    replace_in_study(folder, 'file = "data/wall.csv"', f"file = {json.dumps(path)}")
    with pytest.raises(ConfigError, match=r"data\.file: path .* leaves the study folder"):
        load_study(folder)


def test_absolute_data_path_outside_the_study_is_allowed(guarded: Path) -> None:
    folder = wall_copy(guarded / "study")
    outside = guarded / "elsewhere" / "wall.csv"
    outside.parent.mkdir()
    shutil.move(folder / "data" / "wall.csv", outside)
    replace_in_study(folder, 'file = "data/wall.csv"', f"file = {json.dumps(str(outside))}")
    study = load_study(folder)
    assert study.data.file == outside
    assert load_measured(study).n > 0


@pytest.mark.parametrize(
    ("command", "old", "new", "message"),
    [
        (RECORD, 'output_dir = "out"', 'output_dir = "../out"', r"output_dir: path .* leaves"),
        (RECORD, '"params.tmpl" = ', '"../params.tmpl" = ', r"templates: path .* leaves"),
        (RECORD, '= "params.txt"', '= "../../params.txt"', "must be a relative path inside"),
        (RECORD, 'file = "out.csv"', 'file = "../out.csv"', "must be a relative path inside"),
        (["../record.py", "x"], "", "", r"command: path '../record.py' leaves"),
        (["./sub/../../record.py"], "", "", r"command: path .* leaves"),
    ],
)
def test_relative_paths_of_the_simulator_cannot_leave(
    guarded: Path, command: list[str], old: str, new: str, message: str
) -> None:
    folder = command_study(guarded / "study", command)
    replace_in_study(folder, old, new)
    with pytest.raises(ConfigError, match=message):
        load_study(folder)


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ('type = "fmu"\nfmu = "../../wall.fmu"\noutputs = { heat_flux_in = "q" }', "leaves"),
        ('type = "energyplus"\nmodel = "../m.idf"\nweather = "from-forcing"', "leaves"),
    ],
)
def test_model_files_cannot_leave_the_study(guarded: Path, section: str, message: str) -> None:
    folder = command_study(guarded / "study", RECORD)
    toml = (folder / "study.toml").read_text(encoding="utf-8")
    start = toml.index('type = "command"')
    end = toml.index("[parameters.r_wall]")
    (folder / "study.toml").write_text(toml[:start] + section + "\n\n" + toml[end:])
    with pytest.raises(ConfigError, match=message):
        load_study(folder)


# --------------------------------------------------------------------------- the source


SHELL_CALLS = {"system", "popen", "getoutput", "getstatusoutput", "spawnlp", "execlp"}


def _shell_uses(tree: ast.AST) -> list[str]:
    """Calls that could hand a string to a shell or an interpreter."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")
        if name in {"eval", "exec"} | SHELL_CALLS:
            found.append(f"line {node.lineno}: {name}()")
        for keyword in node.keywords:
            literal_false = isinstance(keyword.value, ast.Constant) and not keyword.value.value
            if keyword.arg == "shell" and not literal_false:
                found.append(f"line {node.lineno}: shell={ast.unparse(keyword.value)}")
    return found


def test_the_package_never_calls_a_shell() -> None:
    """No shell=True, os.system, os.popen, eval or exec anywhere in src/bayescal."""
    package = REPO / "src" / "bayescal"
    files = sorted(package.rglob("*.py"))
    assert len(files) > 20  # the scan sees the package
    found = {
        str(path.relative_to(package)): uses
        for path in files
        if (uses := _shell_uses(ast.parse(path.read_text(encoding="utf-8"))))
    }
    assert found == {}


def test_the_scan_finds_shell_calls() -> None:
    """The scan above would see a shell call (so its empty result means something)."""
    code = "import os, subprocess\nos.system('x')\nsubprocess.run('x', shell=flag)\neval('1')\n"
    assert _shell_uses(ast.parse(code)) == [
        "line 2: system()",
        "line 3: shell=flag",
        "line 4: eval()",
    ]
