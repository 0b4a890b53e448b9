"""The MCMC engine: samplers, several chains, checkpoints, diagnostics, NUTS.

Generic: it knows nothing about emulators or calibration. The emulator's
training (:mod:`bayescal.emulator.training`), the calibration
(:mod:`bayescal.calibration`) and the difference process
(:mod:`bayescal.discrepancy`) all run their chains here.

* :mod:`~bayescal.mcmc.samplers` -- Metropolis-within-Gibbs (one chain, or
  many in lockstep), adaptive block Metropolis;
* :mod:`~bayescal.mcmc.chains` -- several chains in processes, serially or
  vectorised, seeded from one root seed;
* :mod:`~bayescal.mcmc.checkpoint` -- snapshots, so a killed run resumes bit for bit;
* :mod:`~bayescal.mcmc.diagnostics` -- R-hat, ESS, MCSE (ArviZ) and warnings;
* :mod:`~bayescal.mcmc.nuts` -- NUTS with JAX/BlackJAX (optional extra).

ArviZ is imported only when diagnostics are computed, JAX only by NUTS.
"""

from bayescal.mcmc.chains import BACKENDS, ChainBackend, Chains, dispersed_starts, run_chains
from bayescal.mcmc.diagnostics import Diagnostics, diagnose, to_inference_data
from bayescal.mcmc.samplers import (
    AdaptiveMetropolis,
    LockstepTarget,
    LogDensityError,
    MetropolisWithinGibbs,
    Sampler,
    SamplerResult,
    as_lockstep,
    run_lockstep,
)

__all__ = [
    "BACKENDS",
    "AdaptiveMetropolis",
    "ChainBackend",
    "Chains",
    "Diagnostics",
    "LockstepTarget",
    "LogDensityError",
    "MetropolisWithinGibbs",
    "Sampler",
    "SamplerResult",
    "as_lockstep",
    "diagnose",
    "dispersed_starts",
    "run_chains",
    "run_lockstep",
    "to_inference_data",
]
