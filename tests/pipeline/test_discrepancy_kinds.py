"""Which in-likelihood discrepancy (``[outputs.errors.NAME] discrepancy = ...``).

``true`` / ``"conditions"`` is a GP over the periods' conditions, ``"independent"``
a misfit of its own in every period, ``"both"`` their sum (docs/method.md section
4a). The algebra is checked against dense Gaussians in
``tests/emulator/test_noise.py`` (the likelihood) and
``tests/calibration/test_conditional.py`` (the conditioned prediction); here the
study file, the coordinates it makes and the errors it refuses.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayescal.config import load_study
from bayescal.emulator.noise import ObservationModel, OutputNoise
from bayescal.errors import ConfigError
from bayescal.examples import copy_example

OUTPUT = "heating_power"


def _with_kind(tmp_path: Path, value: str, phase: bool = False) -> Path:
    """The co-heating box example with ``discrepancy = value`` (and the phase on)."""
    folder = copy_example("box-coheating", tmp_path / "box")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    assert text.count("\ndiscrepancy = true") == 1
    text = text.replace("\ndiscrepancy = true", f"\ndiscrepancy = {value}")
    if phase:
        head, tail = text.split("\n[discrepancy]\n")
        assert tail.count("\nenabled = false") == 1
        text = head + "\n[discrepancy]\n" + tail.replace("\nenabled = false", "\nenabled = true")
    path.write_text(text, encoding="utf-8")
    return folder


@pytest.mark.parametrize("kind", ["conditions", "independent", "both", "orthogonal"])
def test_the_study_file_states_the_kind(tmp_path: Path, kind: str) -> None:
    study = load_study(_with_kind(tmp_path, f'"{kind}"'))
    assert study.outputs.errors[OUTPUT].discrepancy == kind
    assert study.outputs.calibration_dump()["errors"][OUTPUT]["discrepancy"] == kind


def test_true_is_kept_as_written(tmp_path: Path) -> None:
    # the shipped examples say true: their stage keys must not change
    study = load_study(copy_example("box-coheating", tmp_path / "box"))
    assert study.outputs.calibration_dump()["errors"][OUTPUT]["discrepancy"] is True


def test_the_free_float_example_declares_the_conditions_only(tmp_path: Path) -> None:
    # chosen on its training days (docs/validation/case-studies-log.md): "both" was not
    # clearly better on the data made with EnergyPlus at 60 steps per hour
    study = load_study(copy_example("box-freefloat", tmp_path / "ff"))
    assert study.outputs.calibration_dump()["errors"]["temp_air_in"]["discrepancy"] is True


def test_an_unknown_kind_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"discrepancy"):
        load_study(_with_kind(tmp_path, '"daily"'))


@pytest.mark.parametrize("kind", ['"independent"', '"both"', '"orthogonal"'])
def test_the_phase_takes_a_discrepancy_over_the_conditions_only(tmp_path: Path, kind: str) -> None:
    with pytest.raises(ConfigError, match=r"does not combine with the difference-process phase"):
        load_study(_with_kind(tmp_path, kind, phase=True))


@pytest.mark.parametrize(
    ("kind", "names"),
    [
        (True, ("lambda_star", "phi", "delta_rel")),
        ("conditions", ("lambda_star", "phi", "delta_rel")),
        ("independent", ("lambda_star", "phi", "delta_ind")),
        ("both", ("lambda_star", "phi", "delta_rel", "delta_ind")),
        ("orthogonal", ("lambda_star", "phi", "delta_rel")),
        (False, ("lambda_star", "phi")),
    ],
)
def test_each_kind_makes_its_coordinates(kind: bool | str, names: tuple[str, ...]) -> None:
    k = np.eye(4)[:, :2]
    noise = OutputNoise("q", (0, 4), (0, 1), "ar1", discrepancy=kind)  # type: ignore[arg-type]
    model = ObservationModel((noise,), k, np.zeros((4, 3)))
    assert model.names() == names
    over_x, independent = model.discrepancy_variances(
        [0.1, 0.2][: len(model.delta_coordinates)], [2.0, 3.0]
    )
    assert model.orthogonal_outputs == ((0,) if kind == "orthogonal" else ())
    if kind in (True, "conditions", "both", "orthogonal"):
        assert over_x is not None
        np.testing.assert_allclose(over_x, [0.2, 0.3])
    else:
        assert over_x is None
    if kind in ("independent", "both"):
        assert independent is not None
        np.testing.assert_allclose(independent, [0.4, 0.6] if kind == "both" else [0.2, 0.3])
    else:
        assert independent is None


def test_a_kind_the_model_does_not_know_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"discrepancy must be true, false or one of"):
        OutputNoise("q", (0, 4), (0, 1), discrepancy="daily")  # type: ignore[arg-type]
