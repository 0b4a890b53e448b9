"""``[calibration]``: the MCMC of theta*, the precisions and the error parameters (eq. 16)."""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from bayescal.config.base import Section, field_doc

__all__ = ["CalibrationSection"]


class CalibrationSection(Section):
    """``[calibration]``: MCMC for theta* and the precisions."""

    chains: int = field_doc("Independent chains (>= 4 for R-hat).", 4, default=4, ge=4)
    burn: int = field_doc("Burn-in iterations per chain.", 2000, default=2000, ge=0)
    samples: int = field_doc("Iterations kept per chain.", 5000, default=5000, ge=1)
    seed: int | None = field_doc(
        "Seed; derived from [study].seed if omitted.", 2, default=None, ge=0
    )
    sampler: Literal["mwg", "nuts"] = field_doc(
        "MCMC sampler: 'mwg' (Metropolis-within-Gibbs) or 'nuts' (No-U-Turn with JAX, in a "
        'spawned process; needs `pip install "bayescal[hmc]"`; burn is its warm-up, 500 '
        "burn + 1000 samples are plenty; no checkpoints). 'mwg' is the default: on the "
        "virtual wall (30 runs x 25 days, benchmarks/bench_hmc.py) NUTS drew about 3.8x "
        "the bulk ESS of theta* per CPU second while sampling, but its fixed cost (JIT "
        "compilation 5-6.5 CPU s, process start-up 2 s) left a whole default-length "
        "calibration no faster (min ESS per CPU second 386 vs 389, about 10 s each), and "
        "'mwg' needs no extra package and resumes from checkpoints.",
        "nuts",
        default="mwg",
    )
    moves: Literal["gibbs", "joint"] = field_doc(
        "'gibbs': each coordinate moves alone, then the parameters jointly, every sweep. "
        "'joint': from mid burn-in the parameters, lambda* and AR(1) phi move only together "
        "(covariance learnt from them; proposals screened by a stand-in: delayed acceptance)"
        ": Twin House 7-8x the ESS per evaluation; a large block (office) needs a long "
        "burn-in. Check the diagnostics.",
        "joint",
        default="gibbs",
    )
    max_samples: int | None = field_doc(
        "Length by convergence ('mwg'): while a diagnostic fails (an R-hat above 1.01, a bulk "
        "or tail ESS below 400, a stuck chain), the chains are extended from `samples` by "
        "half their kept length at a time, resuming their last snapshots (no sweep is "
        "redone), up to this many kept iterations per chain; a run that stops short says "
        "so. 4 x `samples` if omitted; equal to `samples`: no extension. 'nuts' ignores it.",
        8000,
        default=None,
        ge=1,
    )

    @model_validator(mode="after")
    def _longest(self) -> CalibrationSection:
        if self.max_samples is not None and self.max_samples < self.samples:
            raise ValueError(
                f"max_samples ({self.max_samples}) is below samples ({self.samples}): set "
                "it to at least samples (equal: no extension)"
            )
        return self

    @property
    def most_samples(self) -> int:
        """Most kept iterations per chain: ``max_samples``, else 4 x ``samples``."""
        return 4 * self.samples if self.max_samples is None else self.max_samples

    @property
    def extends(self) -> bool:
        """Whether failing chains may be extended past ``samples`` ('mwg' only)."""
        return self.sampler == "mwg" and self.most_samples > self.samples
