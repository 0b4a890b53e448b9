"""The ``[parameters.<name>]`` tables: calibration parameters and the schema of their priors.

:class:`UniformPriorSpec` and :class:`BetaPriorSpec` are the priors as a study
file writes them; :meth:`Parameter.to_prior` turns one into the prior the
numerical code uses (:class:`bayescal.design.Prior`), carrying the parameter's
unit and description.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Annotated, Literal, Union

from pydantic import Field, model_validator

from bayescal.config.base import Section, field_doc

if TYPE_CHECKING:
    from bayescal.design import Prior

__all__ = [
    "RESERVED_NAMES",
    "BetaPriorSpec",
    "Parameter",
    "PriorSpec",
    "UniformPriorSpec",
    "reserved_name_problems",
]

#: Names the calibration gives its own coordinates and the posterior's variables:
#: the error model's precisions (``lambda``, ``lambda_star``), AR(1) coefficients
#: (``phi``), discrepancy variances (``delta_rel``, ``delta_ind``), the noise SD, the
#: log density and the draws' dimensions. With several calibrated outputs the
#: per-output ones take the output's name after an underscore (``phi_<output>``).
RESERVED_NAMES = ("lambda", "lambda_star", "phi", "delta_rel", "delta_ind", "noise_sd", "lp")
RESERVED_DIMENSIONS = ("chain", "draw")
PER_OUTPUT = ("lambda_star", "phi", "delta_rel", "delta_ind", "noise_sd")


def reserved_name_problems(
    names: Iterable[str], outputs: Sequence[str], section: str = "parameters"
) -> list[str]:
    """``section.<name>: ...`` for each of ``names`` the calibration reserves for itself.

    Parameters
    ----------
    names
        Parameter (or derived quantity) names.
    outputs
        The calibrated outputs (their per-output coordinates are reserved too).
    section
        Where the names are defined, for the key in the message.
    """
    reserved = {*RESERVED_NAMES, *RESERVED_DIMENSIONS}
    reserved |= {f"{kind}_{output}" for kind in PER_OUTPUT for output in outputs}
    listed = ", ".join(
        [*RESERVED_NAMES, *RESERVED_DIMENSIONS, *(f"{kind}_<output>" for kind in PER_OUTPUT)]
    )
    what = "parameter" if section == "parameters" else "quantity"
    return [
        f"{section}.{name}: the name {name!r} is reserved for the calibration's own "
        f"coordinates and variables ({listed}); rename the {what} [{section}.{name}]"
        for name in names
        if name in reserved
    ]


class UniformPriorSpec(Section):
    """Uniform prior on ``[lower, upper]``."""

    distribution: Literal["uniform"] = field_doc("Prior family.", "uniform")
    lower: float = field_doc("Lower bound, in the parameter's unit.", 0.08, allow_inf_nan=False)
    upper: float = field_doc("Upper bound, in the parameter's unit.", 0.16, allow_inf_nan=False)

    @model_validator(mode="after")
    def _bounds(self) -> UniformPriorSpec:
        if not self.lower < self.upper:
            raise ValueError(f"lower bound {self.lower} >= upper bound {self.upper}")
        return self


class BetaPriorSpec(UniformPriorSpec):
    """Beta(a, b) prior stretched over ``[lower, upper]``."""

    distribution: Literal["beta"] = field_doc("Prior family.", "beta")  # type: ignore[assignment]
    a: float = field_doc("First shape parameter. [-]", 1.0, gt=0)
    b: float = field_doc("Second shape parameter. [-]", 2.0, gt=0)


PriorSpec = Annotated[
    Union[UniformPriorSpec, BetaPriorSpec],  # noqa: UP007
    Field(discriminator="distribution"),
]
"""A prior as the study file writes it, told apart by ``distribution``."""


class Parameter(Section):
    """``[parameters.<name>]``: one calibration parameter. The name is an identifier
    (letters, digits, _) other than those the calibration reserves for its own
    coordinates: lambda, lambda_star, phi, delta_rel, delta_ind, noise_sd, lp, chain,
    draw, and lambda_star, phi, delta_rel, delta_ind or noise_sd followed by _ and
    a calibrated output's name."""

    unit: str = field_doc("Unit of nominal and bounds: the SI unit of the targets.", "W/(m·K)", "1")
    nominal: float = field_doc("Nominal (catalogue) value, inside the bounds.", 0.12)
    prior: PriorSpec = field_doc(
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
    screen: bool = field_doc(
        "A screening candidate: `bayescal screen` ranks it with the others, and `bayescal "
        "run` holds it at its nominal value instead of calibrating it (set it to false, or "
        "let `bayescal screen --apply` do so, to calibrate it).",
        True,
        default=False,
    )

    @model_validator(mode="after")
    def _nominal_inside(self) -> Parameter:
        lower, upper = self.prior.lower, self.prior.upper
        if not lower <= self.nominal <= upper:
            raise ValueError(
                f"nominal {self.nominal} is outside the prior bounds [{lower}, {upper}]"
            )
        return self

    def to_prior(self) -> Prior:
        """The prior of :mod:`bayescal.design`, with this parameter's unit and description."""
        from bayescal.design import prior_from_spec  # scipy.stats.qmc: not needed to validate

        spec = self.prior
        a, b = getattr(spec, "a", None), getattr(spec, "b", None)
        return prior_from_spec(
            spec.distribution,
            spec.lower,
            spec.upper,
            a,
            b,
            unit=self.unit,
            description=self.description,
        )


class DerivedSpec(Section):
    """``[derived.<name>]``: a quantity computed from the parameters at every posterior draw."""

    expression: str = field_doc(
        "Arithmetic of parameter names, numbers, + - * / ** and log, log10, exp, sqrt, abs "
        "(e.g. the wall's resistance '0.3 / k_brick + 0.08 / k_eps').",
        "0.3 / k_brick + 0.08 / k_eps",
    )
    unit: str = field_doc("Unit of the result, for tables and reports.", "m²·K/W", default="")
    description: str = field_doc("Text for reports.", "resistance of brick and EPS", default="")
