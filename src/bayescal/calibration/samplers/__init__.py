"""MCMC samplers behind one small protocol (see :mod:`.base`).

* :class:`MetropolisWithinGibbs` — adaptive, one coordinate at a time
  (Roberts & Rosenthal 2009); the default for emulator hyperparameters.
* :class:`AdaptiveMetropolis` — block random walk with Haario-adapted
  covariance; for a few strongly correlated parameters.
"""

from bayescal.calibration.samplers.base import (
    Box,
    LogDensity,
    LogDensityError,
    Sampler,
    SamplerResult,
)
from bayescal.calibration.samplers.mwg import MetropolisWithinGibbs
from bayescal.calibration.samplers.rwm import AdaptiveMetropolis

__all__ = [
    "AdaptiveMetropolis",
    "Box",
    "LogDensity",
    "LogDensityError",
    "MetropolisWithinGibbs",
    "Sampler",
    "SamplerResult",
]
