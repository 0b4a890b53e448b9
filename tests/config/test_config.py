"""The study file: loading, validation messages, hashing, documentation of every field."""

from __future__ import annotations

import copy
import shutil
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import pydantic
import pytest

import bayescal.config
from bayescal.config import (
    BoxSimulator,
    Study,
    WallSimulator,
    build_simulator,
    load_study,
    study_from_dict,
)
from bayescal.design import BetaPrior, UniformPrior
from bayescal.errors import ConfigError
from bayescal.simulators.box import TestBox
from bayescal.simulators.fvm import Layer
from bayescal.simulators.wall import MultilayerWall
from bayescal.simulators.wrappers import TargetedSimulator
from paths import FIXTURES

FIXTURE = FIXTURES / "wall-study"
BASE = tomllib.loads((FIXTURE / "study.toml").read_text(encoding="utf-8"))


def _validate(edit: Callable[[dict[str, Any]], object]) -> Study:
    raw = copy.deepcopy(BASE)
    edit(raw)
    return study_from_dict(raw, root=FIXTURE)


def test_load_fixture_from_folder_and_file() -> None:
    by_folder, by_file = load_study(FIXTURE), load_study(FIXTURE / "study.toml")
    assert by_folder == by_file
    assert by_folder.root == FIXTURE
    assert by_folder.path == FIXTURE / "study.toml"
    assert by_folder.data.file == FIXTURE / "wall.csv"
    assert by_folder.study.output_dir == FIXTURE / "out"
    assert by_folder.data.format == "csv"  # inferred from the extension
    assert by_folder.data.step.total_seconds() == 1800
    assert by_folder.boundary_conditions == ("temp_surf_out", "temp_surf_in")
    assert by_folder.parameters["cp_fb"].prior.distribution == "beta"
    assert by_folder.design.runs == 20
    assert by_folder.calibration.chains == 4


def test_priors_are_the_design_priors_with_unit_and_description() -> None:
    study = _validate(lambda raw: raw["parameters"]["k_cb"].update(description="blocks"))
    priors = study.priors()
    assert list(priors) == list(study.parameters)
    k_cb, cp_fb = priors["k_cb"], priors["cp_fb"]
    assert isinstance(k_cb, UniformPrior)
    assert (k_cb.lower, k_cb.upper, k_cb.unit, k_cb.description) == (
        0.08,
        0.16,
        "W/(m·K)",
        "blocks",
    )
    assert isinstance(cp_fb, BetaPrior)
    assert (cp_fb.a, cp_fb.b, cp_fb.unit, cp_fb.description) == (1.0, 2.0, "J/(kg·K)", "")
    assert study.parameters["cp_fb"].to_prior() == cp_fb
    # The study file's schema and the runtime priors are two families with two names.
    assert not {"UniformPrior", "BetaPrior", "Prior"} & set(bayescal.config.__all__)


def test_study_is_frozen() -> None:
    study = load_study(FIXTURE)
    with pytest.raises(pydantic.ValidationError, match="frozen"):
        study.design = study.design


def test_config_hash_is_stable_location_independent_and_value_sensitive(tmp_path: Path) -> None:
    h = load_study(FIXTURE).config_hash()
    assert len(h) == 64
    assert h == load_study(FIXTURE).config_hash()
    moved = tmp_path / "elsewhere"
    shutil.copytree(FIXTURE, moved)
    assert load_study(moved).config_hash() == h
    text = (moved / "study.toml").read_text().replace("runs = 20", "runs = 21")
    (moved / "study.toml").write_text(text)
    assert load_study(moved).config_hash() != h


def test_absolute_data_path_may_lie_outside(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere.csv"
    study = _validate(lambda r: r["data"].update(file=str(target)))
    assert study.data.file == target
    inside = _validate(lambda r: r["data"].update(file="sub/../wall.csv"))
    assert inside.data.file == FIXTURE / "wall.csv"


def _set(*keys: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(raw: dict[str, Any]) -> None:
        node = raw
        for key in keys[:-1]:
            node = node.setdefault(key, {})
        node[keys[-1]] = value

    return edit


def _pop(*keys: str) -> Callable[[dict[str, Any]], None]:
    def edit(raw: dict[str, Any]) -> None:
        node = raw
        for key in keys[:-1]:
            node = node[key]
        node.pop(keys[-1])

    return edit


def _then(*edits: Callable[[dict[str, Any]], object]) -> Callable[[dict[str, Any]], None]:
    def edit(raw: dict[str, Any]) -> None:
        for step in edits:
            step(raw)

    return edit


def _rename(old: str, new: str) -> Callable[[dict[str, Any]], None]:
    return lambda raw: raw.__setitem__(new, raw.pop(old))


def _bounds(lower: float, upper: float) -> Callable[[dict[str, Any]], None]:
    def edit(raw: dict[str, Any]) -> None:
        raw["parameters"]["k_cb"]["prior"].update(lower=lower, upper=upper)

    return edit


def _columns(name: str, spec: dict[str, Any]) -> Callable[[dict[str, Any]], None]:
    return lambda raw: raw["data"]["columns"].__setitem__(name, spec)


BAD = [
    (_rename("periods", "peroids"), r"unknown key 'peroids'; did you mean 'periods'\?"),
    (_bounds(0.16, 0.08), r"parameters\.k_cb\.prior: lower bound 0\.16 >= upper bound 0\.08$"),
    (
        _set("parameters", "k_cb", "nominal", value=0.5),
        r"nominal 0\.5 is outside .*\[0\.08, 0\.16\]",
    ),
    (
        _set("data", "columns", "temp_surf_out", "unit", value="kW"),
        r"data\.columns\.temp_surf_out\.unit: 'kW' is a power unit, .* is a temperature",
    ),
    (
        _set("data", "columns", "temp_surf_out", "unit", value="furlongs"),
        r"data\.columns\.temp_surf_out\.unit: unknown unit 'furlongs'",
    ),
    (
        _columns("temp_surf_inn", {"source": "T_si", "unit": "degC"}),
        r"'temp_surf_inn' is not a glossary name; did you mean 'temp_surf_in'\?",
    ),
    (
        _set("data", "file", value="../x.csv"),
        r"data\.file: path '\.\./x\.csv' leaves the study folder",
    ),
    (
        _set("data", "tim_column", value="t"),
        r"unknown key 'data\.tim_column'; did you mean 'data\.time_column'",
    ),
    (
        _set("data", "file", value="wall.xls"),
        r"cannot tell the format of 'wall\.xls'.*data\.format",
    ),
    (_set("data", "step", value="30"), r"data\.step: expected a duration with a unit .* got '30'"),
    (_set("data", "step", value=1800), r"data\.step: expected a duration .* got 1800"),
    (_set("data", "step", value="-30min"), r"data\.step: must be positive"),
    (_set("data", "time_zone", value="Europe/Brusels"), r"did you mean 'Europe/Brussels'"),
    (_set("data", "epoch", value="2013-01-01"), r"data\.epoch: only applies to format modelica"),
    (_pop("data", "time_column"), r"data\.time_column: required for format 'csv'"),
    (_set("data", "start", value="yesterday"), r"data\.start: expected a date-time"),
    (
        _set("data", "columns", "temp_surf_out", "source", value=1.5),
        r"data\.columns\.temp_surf_out\.source: expected a column name or an integer",
    ),
    (
        _set("data", "columns", "temp_surf_out", "source", value=3),
        r"source: give the column name for format 'csv', got 3",
    ),
    (_set("data", "columns", "temp_surf_in", "sign", value=-1), r"-1 on a temperature"),
    (
        _set("simulator", "type", value="foo"),
        r"simulator\.type: unknown value 'foo'; expected one of 'wall', 'box'",
    ),
    (_pop("simulator", "type"), r"simulator\.type: missing; expected one of 'wall', 'box'"),
    (
        lambda r: r["simulator"]["layers"][1].update(thickness=-0.1),
        r"simulator\.layers\[1\]\.thickness: input should be greater than 0, got -0\.1",
    ),
    (
        lambda r: r["simulator"]["layers"][0].update(colour="red"),
        r"unknown key 'simulator\.layers\[0\]\.colour'; valid keys here: name, thickness",
    ),
    (
        _set("simulator", "outputs", value=["temp_interface_9"]),
        r"'temp_interface_9' is not a wall output",
    ),
    (_set("simulator", "solar_absorptance", value=0.5), r"needs boundary = 'air'"),
    (_set("simulator", "scheme", value="rk4"), r"simulator\.scheme: input should be .*got 'rk4'"),
    (
        _set("parameters", "k_cb", "targets", value=["concret.conductivity"]),
        r"'concret\.conductivity' is not a target of the wall simulator; did you mean 'concrete",
    ),
    (_set("parameters", "k_cb", "targets", value=["r_si"]), r"'r_si' is not a target"),  # surface
    (
        _set("parameters", "k_cb", "targets", value=["concrete.conductivity", "concrete.density"]),
        r"mixes quantities of different kinds",
    ),
    (
        _set("parameters", "cp_cb", "targets", value=["concrete.conductivity"]),
        r"'concrete\.conductivity' is already set by 'k_cb'",
    ),
    (
        _set("parameters", "k_cb", "unit", value="kW/mK"),
        r"k_cb\.unit: 'kW/mK' is not the unit .* 'W/\(m·K\)'",
    ),
    (
        lambda r: r["parameters"]["k_cb"]["prior"].update(distribution="beta", a=0, b=1),
        r"parameters\.k_cb\.prior\.a: input should be greater than 0, got 0",
    ),
    (
        lambda r: r["parameters"]["k_cb"]["prior"].update(distribution="normal"),
        r"parameters\.k_cb\.prior\.distribution: unknown value 'normal'",
    ),
    (
        lambda r: r["parameters"]["k_cb"]["prior"].update(lowr=0.1),
        r"unknown key 'parameters\.k_cb\.prior\.lowr'; "
        r"did you mean 'parameters\.k_cb\.prior\.lower'",
    ),
    (_set("parameters", value={}), r"no parameters; define at least one"),
    (
        _set("parameters", "k-cb", value=BASE["parameters"]["k_cb"]),
        r"parameter names are identifiers",
    ),
    (
        _set("outputs", "calibrate", value=["heat_flux_out"]),
        r"'heat_flux_out' is not mapped in \[data\.columns\]",
    ),
    (
        _set("outputs", "calibrate", value=["temp_surf_in"]),
        r"'temp_surf_in' is an input of the wall",
    ),
    (_pop("data", "columns", "temp_surf_out"), r"needs the boundary condition 'temp_surf_out'"),
    (
        _set("periods", "test_fraction", value=0.2),
        r"exactly one of test_samples and test_fraction, got both",
    ),
    (
        _pop("periods", "test_samples"),
        r"exactly one of test_samples and test_fraction, got neither",
    ),
    (
        _set("periods", "length", value="7min"),
        r"periods\.length: 7min is not a multiple of data\.step 30min",
    ),
    (_set("periods", "length", value=1), r"a period needs at least 2 samples"),
    (_set("design", "runs", value=4), r"design\.runs: 4 runs for 3 parameters; at least 5"),
    (_set("design", "optimization", value="maximin"), r"design\.optimization: input should be"),
    (
        _set("emulator", value={"pca_components": 3, "pca_variance": 0.9}),
        r"pca_variance or pca_components",
    ),
    (
        _set("calibration", "chains", value=2),
        r"calibration\.chains: .*greater than or equal to 4, got 2",
    ),
    (
        _set("runner", value={"backend": "serial", "scheduler": "tcp://x:1"}),
        r"scheduler applies to backend 'dask'",
    ),
    (_pop("study"), r"study: missing required key"),
    # names the calibration gives its own coordinates and variables
    *(
        (
            lambda raw, name=name: raw["parameters"].__setitem__(
                name, raw["parameters"].pop("cp_fb")
            ),
            rf"parameters\.{name}: the name '{name}' is reserved .*\(lambda, lambda_star, phi",
        )
        for name in ("lambda", "lambda_star", "phi", "delta_rel", "lp", "chain", "phi_heat_flux_in")
    ),
    (
        _set("derived", value={"noise_sd": {"expression": "k_cb"}}),
        r"derived\.noise_sd: the name 'noise_sd' is reserved .*rename the quantity",
    ),
]


@pytest.mark.parametrize(("edit", "match"), BAD)
def test_bad_configs(edit: Callable[[dict[str, Any]], object], match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        _validate(edit)
    assert "\n" not in str(info.value)


def test_many_errors_in_one_line() -> None:
    def edit(raw: dict[str, Any]) -> None:
        _bounds(0.16, 0.08)(raw)
        raw["design"]["runz"] = 3
        raw["data"]["step"] = "fast"

    with pytest.raises(ConfigError) as info:
        _validate(edit)
    message = str(info.value)
    assert message.count("; ") >= 2
    assert "\n" not in message
    for part in ("lower bound 0.16 >= upper bound 0.08", "unknown key 'design.runz'", "data.step"):
        assert part in message


def test_toml_syntax_error_names_file_and_line(tmp_path: Path) -> None:
    (tmp_path / "study.toml").write_text('[study]\nname = "x"\nseed = = 3\n')
    with pytest.raises(ConfigError, match=r"study\.toml: invalid TOML: .*line 3"):
        load_study(tmp_path)


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16"])
def test_a_study_file_with_a_byte_order_mark_loads(tmp_path: Path, encoding: str) -> None:
    """Windows editors write a BOM (Notepad's "Unicode" is UTF-16): the study reads."""
    folder = tmp_path / "study"
    shutil.copytree(FIXTURE, folder)
    text = (folder / "study.toml").read_text(encoding="utf-8")
    (folder / "study.toml").write_bytes(text.encode(encoding))
    assert load_study(folder).config_hash() == load_study(FIXTURE).config_hash()


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("runs", "30", r"design\.runs: expected a number, got the text '30'"),
        ("runs", 30.0, r"design\.runs: expected a whole number .*got 30\.0"),
        ("runs", True, r"design\.runs: expected a number, got true"),
        ("seed", 1.5, r"design\.seed: expected a whole number"),
    ],
)
def test_integers_are_integers(key: str, value: object, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        _validate(lambda raw: raw.setdefault("design", {}).__setitem__(key, value))


def test_numbers_in_lists_and_tables_are_strict() -> None:
    def edit(raw: dict[str, Any]) -> None:
        raw["parameters"]["k_cb"]["nominal"] = "0.12"
        raw["simulator"]["layers"][0]["thickness"] = "0.027"

    with pytest.raises(ConfigError) as info:
        _validate(edit)
    assert "parameters.k_cb.nominal: expected a number, got the text '0.12'" in str(info.value)
    assert "simulator.layers[0].thickness: expected a number" in str(info.value)
    # whole numbers stay good floats, and numpy integers good integers
    import numpy as np

    study = _validate(lambda raw: raw["design"].__setitem__("runs", np.int64(12)))
    assert study.design.runs == 12
    study = _validate(lambda raw: raw["parameters"]["cp_cb"].__setitem__("nominal", 800))
    assert study.parameters["cp_cb"].nominal == 800.0


def test_missing_study(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"no study\.toml in folder"):
        load_study(tmp_path)
    with pytest.raises(ConfigError, match="file not found"):
        load_study(tmp_path / "other.toml")
    (tmp_path / "study.toml").symlink_to("again.toml")
    (tmp_path / "again.toml").symlink_to("study.toml")
    with pytest.raises(ConfigError, match=r"symbolic link loop \(study\.toml -> again\.toml"):
        load_study(tmp_path)


def test_modelica_and_epw_sources() -> None:
    def modelica(raw: dict[str, Any]) -> None:
        raw["data"] = {
            "file": "table.txt",
            "epoch": "2013-01-01T00:00:00",
            "time_zone": "UTC+01:00",
            "step": "10min",
            "columns": {
                "temp_surf_out": {"source": 18, "unit": "degC"},
                "temp_surf_in": {"source": 14, "unit": "degC"},
                "heat_flux_in": {"source": 15, "unit": "W/m2"},
            },
        }

    study = _validate(modelica)
    assert study.data.format == "modelica"
    assert study.data.epoch is not None
    with pytest.raises(ConfigError, match=r"Modelica tables need a column index >= 1"):
        _validate(_then(modelica, lambda r: r["data"]["columns"]["temp_surf_in"].update(source=0)))
    with pytest.raises(ConfigError, match=r"data\.epoch: required for Modelica"):
        _validate(_then(modelica, lambda r: r["data"].pop("epoch")))

    def epw(raw: dict[str, Any]) -> None:
        modelica(raw)
        raw["data"] = {k: v for k, v in raw["data"].items() if k not in ("epoch", "time_zone")}
        raw["data"]["file"] = "weather.epw"
        raw["data"]["step"] = "1h"
        raw["data"]["columns"]["temp_surf_out"]["source"] = "temp_air_out"

    assert _validate(epw).data.format == "epw"
    with pytest.raises(ConfigError, match=r"'temp_ar_out' is not an EPW field; did you mean"):
        _validate(
            _then(epw, lambda r: r["data"]["columns"]["temp_surf_out"].update(source="temp_ar_out"))
        )
    with pytest.raises(ConfigError, match=r"EPW files carry their own time zone"):
        _validate(_then(epw, lambda r: r["data"].update(time_zone="UTC")))


BOX = {
    "type": "box",
    "mode": "freefloat",
    "latitude": 50.69,
    "longitude": 4.53,
    "constants": {"c_wall": 800.0},
}


def _box(raw: dict[str, Any]) -> None:
    raw["simulator"] = dict(BOX)
    raw["data"]["columns"] = {
        name: {"source": "T_se", "unit": "degC"} for name in ("temp_air_out", "temp_air_in")
    }
    raw["data"]["columns"] |= {name: {"source": "q_si", "unit": "W/m2"} for name in ("ghi", "dhi")}
    raw["data"]["columns"]["wind_speed"] = {"source": "q_si", "unit": "m/s"}
    raw["outputs"]["calibrate"] = ["temp_air_in"]
    raw["parameters"] = {
        "k_wall": {
            "unit": "W/mK",
            "nominal": 0.125,
            "prior": {"distribution": "uniform", "lower": 0.05, "upper": 0.2},
            "targets": ["k_wall"],
        },
        "t_w": {
            "unit": "1",
            "nominal": 0.61,
            "prior": {"distribution": "beta", "lower": 0.5, "upper": 0.72, "a": 1, "b": 2},
            "targets": ["t_w"],
        },
    }


def test_box_study() -> None:
    study = _validate(_box)
    assert isinstance(study.simulator, BoxSimulator)
    assert study.simulator.output_names() == ("temp_air_in",)
    with pytest.raises(
        ConfigError, match=r"'k_wal' is not a target of the box simulator; did you mean 'k_wall'"
    ):
        _validate(_then(_box, lambda r: r["parameters"]["k_wall"].update(targets=["k_wal"])))
    with pytest.raises(ConfigError, match=r"'c_wal' is not a box constant; did you mean 'c_wall'"):
        _validate(_then(_box, lambda r: r["simulator"].update(constants={"c_wal": 1.0})))
    with pytest.raises(ConfigError, match=r"needs the boundary condition 'wind_speed'"):
        _validate(_then(_box, lambda r: r["data"]["columns"].pop("wind_speed")))


def test_box_sky_air_split_reaches_the_simulator() -> None:
    def with_split(value: bool) -> Callable[[dict[str, Any]], None]:
        return _then(_box, lambda r: r["simulator"].update(sky_air_split=value))

    for setting in (None, False, True):
        sim = build_simulator(_validate(_box if setting is None else with_split(setting)))
        assert isinstance(sim, TargetedSimulator)
        assert isinstance(sim.inner, TestBox)
        assert sim.inner.sky_air_split is (setting is not False)  # on by default


def test_box_window_model_reaches_the_simulator() -> None:
    for setting in (None, "transmittance", "layers"):
        study = (
            _box
            if setting is None
            else _then(_box, lambda r, v=setting: r["simulator"].update(window_model=v))
        )
        sim = build_simulator(_validate(study))
        assert isinstance(sim, TargetedSimulator)
        assert isinstance(sim.inner, TestBox)
        assert sim.inner.window_model == (setting or "transmittance")  # the paper's by default
    with pytest.raises(ConfigError, match="window_model"):
        _validate(_then(_box, lambda r: r["simulator"].update(window_model="tinted")))


def test_simulator_sections_agree_with_the_simulators() -> None:
    study = load_study(FIXTURE)
    wall_cfg = study.simulator
    assert isinstance(wall_cfg, WallSimulator)
    layers = [Layer(**layer.model_dump()) for layer in wall_cfg.layers]
    cases: tuple[tuple[Literal["surface", "air"], float], ...] = (("surface", 0.0), ("air", 0.6))
    for boundary, alpha in cases:
        cfg = wall_cfg.model_copy(update={"boundary": boundary, "solar_absorptance": alpha})
        wall = MultilayerWall(layers, boundary=boundary, solar_absorptance=alpha)
        assert cfg.input_names() == wall.input_names
        targets = {name: [target] for name, target in enumerate_targets(cfg)}
        MultilayerWall(layers, boundary=boundary, solar_absorptance=alpha, parameters=targets)
    for mode in ("coheating", "freefloat"):
        cfg_box = BoxSimulator.model_validate({**BOX, "mode": mode})
        box = TestBox(mode=mode, latitude=50.0, longitude=4.0)
        assert cfg_box.input_names() == box.input_names
        assert cfg_box.output_names() == box.output_names
        TestBox(mode=mode, latitude=50.0, longitude=4.0, parameters=tuple(cfg_box.target_kinds()))


def enumerate_targets(cfg: WallSimulator) -> list[tuple[str, str]]:
    """One parameter per target the configuration accepts (the simulator must accept them)."""
    return [(f"p{i}", target) for i, target in enumerate(cfg.target_kinds())]


def _models(model: type[pydantic.BaseModel], seen: set[type[pydantic.BaseModel]]) -> None:
    if model in seen:
        return
    seen.add(model)
    for field in model.model_fields.values():
        stack = [field.annotation]
        while stack:
            node = stack.pop()
            if isinstance(node, type) and issubclass(node, pydantic.BaseModel):
                _models(node, seen)
            stack.extend(getattr(node, "__args__", ()))


def test_every_field_is_documented_with_examples() -> None:
    seen: set[type[pydantic.BaseModel]] = set()
    _models(Study, seen)
    assert {WallSimulator, BoxSimulator} <= seen
    undocumented = [
        f"{model.__name__}.{name}"
        for model in seen
        for name, field in model.model_fields.items()
        if not field.description or (model is not Study and not field.examples)
    ]
    assert undocumented == []
    schema = Study.model_json_schema()  # the reference generator's input must build
    assert "simulator" in schema["properties"]


def test_names_near_the_reserved_ones_are_parameters_like_any() -> None:
    def rename(raw: dict[str, Any]) -> None:
        raw["parameters"]["phi_wall"] = raw["parameters"].pop("cp_fb")
        raw["parameters"]["lambda_glass"] = raw["parameters"].pop("cp_cb")

    study = _validate(rename)
    assert set(study.parameters) == {"k_cb", "phi_wall", "lambda_glass"}


def test_path_problem_says_why_a_file_cannot_be_read(tmp_path: Path) -> None:
    from bayescal.config.base import path_problem

    (tmp_path / "file.idf").write_text("x", encoding="utf-8")
    (tmp_path / "loop.idf").symlink_to("loop.idf")
    (tmp_path / "to-file.idf").symlink_to("file.idf")
    assert path_problem(tmp_path / "file.idf") is None
    assert path_problem(tmp_path / "to-file.idf") is None
    assert path_problem(tmp_path) == "not a file"
    assert path_problem(tmp_path / "none.idf") == "file not found"
    assert path_problem(tmp_path / "loop.idf") == "symbolic link loop (loop.idf -> loop.idf)"
