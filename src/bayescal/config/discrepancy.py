"""``[discrepancy]``: the settings of the difference process (the paper's eqs. 18–25)."""

from __future__ import annotations

from bayescal.config.base import Section, field_doc

__all__ = ["DiscrepancySection"]


class DiscrepancySection(Section):
    """``[discrepancy]``: the difference process Delta(x) (the paper's eqs. 18–25)."""

    enabled: bool = field_doc("Estimate Delta(x).", True, default=False)
    realisations: int = field_doc("Posterior realisations b per update.", 50, default=50, ge=2)
    update_interval: int = field_doc("MCMC iterations between updates.", 100, default=100, ge=1)
    burn: int | None = field_doc(
        "Burn-in iterations per chain of the discrepancy phase (lockstep chains of "
        "Metropolis-within-Gibbs in whitened coordinates with Delta updates, whatever "
        "[calibration] sampler says); [calibration] burn if omitted. Set it when the "
        "calibration uses 'nuts', whose short runs are too short for these chains.",
        4000,
        default=None,
        ge=0,
    )
    samples: int | None = field_doc(
        "Iterations kept per chain of the discrepancy phase before its first convergence "
        "check; [calibration] samples if omitted.",
        10000,
        default=None,
        ge=1,
    )
    max_samples: int | None = field_doc(
        "Most iterations kept per chain: the chains are extended from `samples` (by half "
        "their length at a time) until every R-hat <= 1.01 and every bulk and tail ESS >= "
        "400, at most to this length; a phase that stops short says so. 4 x `samples` "
        "if omitted; equal to `samples`: no extension.",
        40000,
        default=None,
        ge=1,
    )
