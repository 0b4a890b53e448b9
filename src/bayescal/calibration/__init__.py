"""Calibration: samplers, several chains, and their diagnostics.

ArviZ is imported only when diagnostics are computed.
"""

from bayescal.calibration.chains import Chains, dispersed_starts, run_chains
from bayescal.calibration.diagnostics import Diagnostics, diagnose, to_inference_data
from bayescal.calibration.samplers import (
    AdaptiveMetropolis,
    LogDensityError,
    MetropolisWithinGibbs,
    Sampler,
    SamplerResult,
)

__all__ = [
    "AdaptiveMetropolis",
    "Chains",
    "Diagnostics",
    "LogDensityError",
    "MetropolisWithinGibbs",
    "Sampler",
    "SamplerResult",
    "diagnose",
    "dispersed_starts",
    "run_chains",
    "to_inference_data",
]
