"""MCMC samplers behind one small protocol (see :mod:`.base`).

* :class:`MetropolisWithinGibbs` — adaptive, one coordinate at a time
  (Roberts & Rosenthal 2009); the default for emulator hyperparameters and
  the calibration. :func:`run_lockstep` runs several of its chains together
  with one batched log-density call per update; both follow the batch
  schedule of :mod:`.schedule` (adaptation, snapshots).
* :class:`AdaptiveMetropolis` — block random walk with Haario-adapted
  covariance; for a few strongly correlated parameters.
"""

from bayescal.mcmc.samplers.base import (
    Box,
    LogDensity,
    LogDensityError,
    Sampler,
    SamplerResult,
)
from bayescal.mcmc.samplers.lockstep import (
    LockstepCapable,
    LockstepTarget,
    RowLoop,
    Stateless,
    as_lockstep,
    run_lockstep,
)
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs
from bayescal.mcmc.samplers.rwm import AdaptiveMetropolis

__all__ = [
    "AdaptiveMetropolis",
    "Box",
    "LockstepCapable",
    "LockstepTarget",
    "LogDensity",
    "LogDensityError",
    "MetropolisWithinGibbs",
    "RowLoop",
    "Sampler",
    "SamplerResult",
    "Stateless",
    "as_lockstep",
    "run_lockstep",
]
