"""The ``[parameters.<name>]`` tables: calibration parameters and their priors."""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from bayescal.config.base import Section, field_doc

__all__ = ["BetaPrior", "Parameter", "Prior", "UniformPrior"]


class UniformPrior(Section):
    """Uniform prior on ``[lower, upper]``."""

    distribution: Literal["uniform"] = field_doc("Prior family.", "uniform")
    lower: float = field_doc("Lower bound, in the parameter's unit.", 0.08, allow_inf_nan=False)
    upper: float = field_doc("Upper bound, in the parameter's unit.", 0.16, allow_inf_nan=False)

    @model_validator(mode="after")
    def _bounds(self) -> UniformPrior:
        if not self.lower < self.upper:
            raise ValueError(f"lower bound {self.lower} >= upper bound {self.upper}")
        return self


class BetaPrior(UniformPrior):
    """Beta(a, b) prior stretched over ``[lower, upper]``."""

    distribution: Literal["beta"] = field_doc("Prior family.", "beta")  # type: ignore[assignment]
    a: float = field_doc("First shape parameter. [-]", 1.0, gt=0)
    b: float = field_doc("Second shape parameter. [-]", 2.0, gt=0)


Prior = Annotated[Union[UniformPrior, BetaPrior], Field(discriminator="distribution")]  # noqa: UP007


class Parameter(Section):
    """``[parameters.<name>]``: one calibration parameter."""

    unit: str = field_doc("Unit of nominal and bounds: the SI unit of the targets.", "W/(m·K)", "1")
    nominal: float = field_doc("Nominal (catalogue) value, inside the bounds.", 0.12)
    prior: Prior = field_doc(
        "Prior: {distribution = 'uniform', lower, upper} or {distribution = 'beta', lower, "
        "upper, a, b}.",
        {"distribution": "uniform", "lower": 0.08, "upper": 0.16},
    )
    targets: list[str] = field_doc(
        "What the value sets: 'layer.property' or r_si, r_se, solar_absorptance (wall); a "
        "constant name (box); 'ObjectType:ObjectName:Field' (energyplus; a name holding ':' "
        "in double quotes); a template placeholder (command); an FMU variable (fmu); "
        "'measured.<output>.offset' or '.gain' (any simulator: a sensor model, reading = "
        "gain * simulated + offset). Several targets share one value.",
        ["concrete.conductivity"],
        ["board_out.specific_heat", "board_in.specific_heat"],
        ["Material:AeratedConcrete:Conductivity"],
        min_length=1,
    )
    description: str = field_doc("Text for reports.", "conductivity of the blocks", default="")

    @model_validator(mode="after")
    def _nominal_inside(self) -> Parameter:
        lower, upper = self.prior.lower, self.prior.upper
        if not lower <= self.nominal <= upper:
            raise ValueError(
                f"nominal {self.nominal} is outside the prior bounds [{lower}, {upper}]"
            )
        return self
