"""The ``[screening]`` section: the Morris design of ``bayescal screen``.

:mod:`bayescal.screening` computes the elementary effects;
:mod:`bayescal.pipeline.screen` runs the design and writes the results.
"""

from __future__ import annotations

from typing import Literal

from pydantic import field_validator

from bayescal.config.base import Section, field_doc

__all__ = ["ScreeningSection"]


class ScreeningSection(Section):
    """``[screening]``: Morris elementary effects of every parameter (``bayescal screen``)."""

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
    seed: int | None = field_doc(
        "Seed of the trajectories and of the bootstrap; derived from [study].seed if omitted.",
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
        "A parameter is proposed for calibration when its mu* reaches this fraction of "
        "the largest mu* for at least one output. [-]",
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
        "Bootstrap resamples of the 95 % confidence intervals of mu*.",
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
