"""The ``[screening]`` section: the design and method of ``bayescal screen``.

``method = "morris"`` (Morris elementary effects over ``trajectories``
trajectories) or ``"sobol"`` (a Latin hypercube of ``runs`` runs, a quick GP
and Sobol indices on it). :mod:`bayescal.screening` computes the indices;
:mod:`bayescal.pipeline.screen` runs the design and writes the results.
"""

from __future__ import annotations

from typing import Literal

from pydantic import field_validator, model_validator

from bayescal.config.base import Section, field_doc, raise_problems

__all__ = ["ScreeningSection"]


class ScreeningSection(Section):
    """``[screening]``: sensitivity of every parameter, Morris or Sobol (``bayescal screen``)."""

    method: Literal["morris", "sobol"] = field_doc(
        "How the parameters are ranked: 'morris' (elementary effects along r trajectories, "
        "r × (k + 1) runs, ranked by mu*) or 'sobol' (a Latin hypercube of `runs` runs, a "
        "GP fitted to each output's statistic, and the first-order and total Sobol indices "
        "S1 and ST of the GP over the prior ranges, ranked by ST; the GP's leave-one-out Q2 "
        "is reported and a Q2 below 0.8 is warned about).",
        "sobol",
        default="morris",
    )
    trajectories: int = field_doc(
        "Morris trajectories r; the design has r × (k + 1) runs for k parameters (10 to 20 "
        "is usual; the confidence intervals of mu* shrink as 1/sqrt(r)).",
        10,
        default=10,
        ge=2,
    )
    levels: int = field_doc(
        "Levels p of the Morris grid on each parameter's prior range (even; the step is "
        "p / (2 (p - 1)) of the range).",
        4,
        default=4,
        ge=2,
        le=20,
    )
    runs: int | None = field_doc(
        "method = 'sobol': runs of the Latin hypercube over the k parameters' prior ranges "
        "(at least k + 2; 10 × k if omitted).",
        60,
        default=None,
        ge=4,
    )
    saltelli: int = field_doc(
        "method = 'sobol': Saltelli base sample N of the Sobol estimates on the GP (a power "
        "of 2; N × (k + 2) GP evaluations, no simulator runs).",
        1024,
        default=1024,
        ge=64,
        le=65536,
    )
    paths: int = field_doc(
        "method = 'sobol': GP posterior sample paths whose Sobol indices give the 95 % "
        "interval of the GP's uncertainty (0: the Saltelli sample's interval only).",
        30,
        default=30,
        ge=0,
        le=1000,
    )
    seed: int | None = field_doc(
        "Seed of the trajectories (or the Latin hypercube), the GP and the bootstrap; "
        "derived from [study].seed if omitted.",
        5,
        default=None,
        ge=0,
    )
    statistic: Literal["mean", "rmse"] = field_doc(
        "The scalar of each output whose sensitivity is measured, over the training "
        "periods: 'mean' (the mean of the simulated series: energy use per clock step, "
        "mean temperature) or 'rmse' (its root mean squared difference from the "
        "measurements).",
        "rmse",
        default="mean",
    )
    threshold: float = field_doc(
        "A parameter is proposed for calibration when its mu* (Morris) or total Sobol "
        "index ST (Sobol) reaches this fraction of the largest for at least one output. ST "
        "is a share of variance, which goes as the square of an effect: 0.01 with Sobol "
        "keeps about what 0.1 keeps with Morris. [-]",
        0.1,
        default=0.1,
        gt=0,
        le=1,
    )
    max_parameters: int | None = field_doc(
        "At most this many parameters are proposed (the most influential first).",
        6,
        default=None,
        ge=1,
    )
    bootstrap: int = field_doc(
        "Bootstrap resamples of the 95 % confidence intervals of mu* (Morris) or of the "
        "Saltelli sample's error of S1 and ST (Sobol).",
        1000,
        default=1000,
        ge=10,
    )

    @field_validator("levels")
    @classmethod
    def _even(cls, value: int) -> int:
        if value % 2:
            raise ValueError(f"levels must be even (Morris's step p / (2 (p - 1))), got {value}")
        return value

    @field_validator("saltelli")
    @classmethod
    def _power_of_two(cls, value: int) -> int:
        if value & (value - 1):
            lower = 1 << (value.bit_length() - 1)
            raise ValueError(
                f"saltelli must be a power of 2 (the Sobol' sequence's balance), got {value}; "
                f"try {lower} or {2 * lower}"
            )
        return value

    @model_validator(mode="after")
    def _method_keys(self) -> ScreeningSection:
        given, problems = self.model_fields_set, []
        own = {"morris": ("trajectories", "levels"), "sobol": ("runs", "saltelli", "paths")}
        for method, keys in own.items():
            if method != self.method:
                problems += [
                    f"screening.{key}: only applies to method = {method!r} (method is "
                    f"{self.method!r})"
                    for key in keys
                    if key in given
                ]
        raise_problems(problems)
        return self

    def sobol_runs(self, parameters: int) -> int:
        """Runs of the Sobol method's Latin hypercube: ``runs``, else 10 per parameter."""
        return self.runs if self.runs is not None else 10 * parameters
