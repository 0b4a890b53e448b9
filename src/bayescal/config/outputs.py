"""``[outputs]``: the measured outputs calibrated on or held out, and their error models.

Each calibrated output may declare its sensor's accuracy (``sd``, a number or
``'<number> <unit>'``, or a range), its error model (white or AR(1)) and a
model discrepancy inside the likelihood (``[outputs.errors.NAME]``); held-out
outputs are predicted but never calibrated on.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import field_validator

from bayescal.config.base import Section, field_doc
from bayescal.errors import ConfigError, DataError
from bayescal.glossary import glossary_quantity
from bayescal.units import spread_to_internal

__all__ = ["OutputError", "OutputsSection", "Spread"]

Spread = float | str


class OutputError(Section):
    """``[outputs.errors.<name>]``: the measurement error model of one measured output
    (calibrated or held out)."""

    model: Literal["white", "ar1"] = field_doc(
        "Errors independent from sample to sample ('white', the paper) or AR(1) within a "
        "period ('ar1': residuals that drift, coefficient sampled). Choose by cross-validation "
        "on the training periods (bayescal compare), not by the test window.",
        "ar1",
        default="white",
    )
    sd: Spread | list[Spread] | None = field_doc(
        "The sensor's accuracy as one standard deviation, or a range [low, high] taken as "
        "the central 95 % interval of the noise SD; a number in the output's unit or text "
        "with a unit ('0.1 W/m2', '0.2 K'). It becomes the prior of the output's observation "
        "precision (centred on it, or spanning the range). Without it, a weak prior lets the "
        "data decide.",
        "0.1 W/m2",
        ["0.05 W/m2", "0.3 W/m2"],
        default=None,
    )

    discrepancy: bool | Literal["conditions", "independent", "both", "orthogonal"] = field_doc(
        "Add a model discrepancy to this output inside the calibration's likelihood. "
        "true or 'conditions': a Gaussian process over the periods' conditions x with the "
        "emulator's correlation and a sampled variance (log-uniform prior from 1e-8 to 1 of "
        "the emulator's), so similar days share their misfit; 'independent': a misfit of "
        "its own in every period (no correlation between periods), which a test day cannot "
        "borrow from the training days; 'both': their sum, each variance sampled; "
        "'orthogonal': the one over the conditions constrained orthogonal to the model's "
        "sensitivities in the parameters at the sampled parameters (Plumlee 2017), so that "
        "it cannot stand in for a change of the parameters. "
        "Systematic misfit then widens the parameters' intervals instead of biasing them "
        "with false confidence. Choose by cross-validation on the training periods "
        "(bayescal compare).",
        True,
        "both",
        default=False,
    )

    relative: bool = field_doc(
        "Errors proportional to the level, as a meter's ('within 3 %'): the output is "
        "calibrated on log(value + floor), so its noise SD, its sd and its bands are "
        "relative (sd is then a fraction, 0.03 or '3 %'). The band of an hour with little "
        "gas is then narrower than that of a morning with a lot. Choose it by "
        "cross-validation on the training periods: bayescal compare ranks it against "
        "absolute errors in the measurements' own units.",
        True,
        default=False,
    )
    floor: Spread | None = field_doc(
        "With relative errors: the level below which the error stops shrinking (a meter's "
        "resolution, a sensor's offset), in the output's unit or text with a unit. Default: "
        "1 % of the mean measured value of the training periods.",
        "0.1 kWh",
        default=None,
    )

    @field_validator("sd")
    @classmethod
    def _sd_shape(cls, value: Any) -> Any:
        if isinstance(value, list) and len(value) != 2:
            raise ValueError(f"give one sd or a range [low, high], got {len(value)} values")
        return value


class OutputsSection(Section):
    """``[outputs]``: the measured outputs to calibrate on."""

    calibrate: list[str] = field_doc(
        "Glossary names of measured outputs, mapped in [data.columns] and produced by the "
        "simulator.",
        ["heat_flux_in"],
        min_length=1,
    )
    errors: dict[str, OutputError] = field_doc(
        "Measurement error model per calibrated output (default: white errors, weak prior); "
        "for a held-out output its sd (required) is the sensor noise of its band.",
        {"heat_flux_in": {"model": "ar1", "sd": "0.1 W/m2"}},
        default_factory=dict,
    )
    held_out: list[str] = field_doc(
        "Measured outputs predicted but never calibrated on: held-out sensors that test the "
        "calibrated model where it was not fitted (a temperature inside the wall when the "
        "flux is calibrated). Each needs [outputs.errors.<name>] sd, the sensor's accuracy; "
        "its band is the simulator re-run at posterior draws plus that noise (needs "
        "[predict] method = 'simulator'). Its metrics are reported on both windows, both "
        "unseen by the calibration.",
        ["temp_interface_2"],
        default_factory=list,
    )

    def calibration_dump(self) -> dict[str, Any]:
        """The section without the held-out outputs (what the emulator and calibration read).

        ``relative`` and ``floor`` enter only where set, so that the stage keys of
        studies written before they existed stay what they were.
        """
        return {
            "calibrate": list(self.calibrate),
            "errors": {
                name: _error_dump(spec)
                for name, spec in self.errors.items()
                if name not in self.held_out
            },
        }

    def phase_problems(self, phase: bool) -> list[str]:
        """What the difference-process phase (``phase``: ``[discrepancy] enabled``) refuses:
        an in-likelihood discrepancy other than over the conditions."""
        if not phase:
            return []
        return [
            f"outputs.errors.{name}.discrepancy: {spec.discrepancy!r} does not combine with "
            "the difference-process phase ([discrepancy] enabled), which takes a discrepancy "
            "over the conditions only; use discrepancy = true, or turn the phase off"
            for name, spec in self.errors.items()
            if spec.discrepancy not in (False, True, "conditions")
        ]

    def relative(self, name: str) -> bool:
        """Whether output ``name`` has errors proportional to its level."""
        spec = self.errors.get(name)
        return spec is not None and spec.relative

    def floor(self, name: str) -> float | None:
        """The stated floor of a relative output in its internal unit (``None``: default)."""
        spec = self.errors.get(name)
        if spec is None or spec.floor is None:
            return None
        return _spread(spec.floor, name, "floor")

    def noise_sd(self, name: str) -> float | tuple[float, float] | None:
        """The stated accuracy of output ``name`` in its internal unit (``None`` if not given).

        Raises
        ------
        bayescal.errors.ConfigError
            For text that is not "<number> <unit>" with a unit of the output's dimension.
        """
        spec = self.errors.get(name)
        if spec is None or spec.sd is None:
            return None
        values = spec.sd if isinstance(spec.sd, list) else [spec.sd]
        read = _fraction if spec.relative else _spread
        out = [read(v, name) for v in values]
        return out[0] if len(out) == 1 else (out[0], out[1])


def _error_dump(spec: OutputError) -> dict[str, Any]:
    dumped = spec.model_dump(mode="json")
    for key in ("relative", "floor"):
        if dumped[key] == OutputError.model_fields[key].default:
            del dumped[key]
    return dumped


def _fraction(value: Spread, name: str, what: str = "sd") -> float:
    """A relative noise SD: a number (0.03) or a percentage ('3 %')."""
    text = str(value).strip()
    try:
        number = float(text[:-1]) / 100.0 if text.endswith("%") else float(text)
    except ValueError:
        raise ConfigError(
            f"outputs.errors.{name}.{what}: {value!r} is not a fraction; with relative = true "
            "the noise SD is a fraction of the level, e.g. 0.03 or '3 %'"
        ) from None
    return number


def _spread(value: Spread, name: str, what: str = "sd") -> float:
    """One noise SD (or floor) in the internal unit of output ``name``."""
    if not isinstance(value, str):
        return float(value)
    parts = value.split(maxsplit=1)
    quantity = glossary_quantity(name)
    try:
        number = float(parts[0])
        if len(parts) == 1:
            return number
        if quantity is None:
            raise DataError(f"{name!r} is not a glossary name, its unit is unknown")
        return spread_to_internal(number, parts[1].strip(), quantity.dimension)
    except (ValueError, DataError) as exc:
        detail = exc.one_line() if isinstance(exc, DataError) else "not a number"
        raise ConfigError(
            f"outputs.errors.{name}.{what}: {value!r} is not '<number> <unit>' ({detail})",
            hint="write e.g. sd = '0.1 W/m2' or a plain number in the output's unit",
        ) from None
