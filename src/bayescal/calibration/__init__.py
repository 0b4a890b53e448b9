"""Calibration: the posterior of theta*, lambda and lambda* (the paper's eq. 16).

* :mod:`~bayescal.calibration.grid` -- what never moves (eigen-decompositions,
  rotated weights), built once and shared by every evaluation;
* :mod:`~bayescal.calibration.kron` -- the likelihood (eq. 12) one point at a
  time by the Kronecker structure; :mod:`~bayescal.calibration.dense` its dense
  reference; :mod:`~bayescal.calibration.batch` ``B`` points at once;
* :mod:`~bayescal.calibration.priors` -- the prior terms;
* :mod:`~bayescal.calibration.target` -- the log posterior, its lockstep form,
  and sampling without diagnostics;
* :mod:`~bayescal.calibration.hmc` -- the same in JAX for NUTS;
* :mod:`~bayescal.calibration.posterior` -- :func:`calibrate` and the
  :class:`Posterior` with its diagnostics;
* :mod:`~bayescal.calibration.conditional` -- an in-likelihood discrepancy
  conditioned on the training residuals, for predictions;
* :mod:`~bayescal.calibration.loo`, :mod:`~bayescal.calibration.cv` and
  :mod:`~bayescal.calibration.heldout` -- leave-one-period-out log predictive
  densities (``bayescal compare``).

The MCMC engine itself (samplers, chains, checkpoints, diagnostics) is
:mod:`bayescal.mcmc`.
"""

from bayescal.calibration.kron import CalibrationAlgebra, KronCalibrationDensity, make_algebra
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.calibration.target import (
    LAMBDA_NAMES,
    BatchedPosterior,
    CalibrationPosterior,
    build_target,
    default_sampler,
    default_starts,
    sample,
)

__all__ = [
    "LAMBDA_NAMES",
    "BatchedPosterior",
    "CalibrationAlgebra",
    "CalibrationPosterior",
    "KronCalibrationDensity",
    "Posterior",
    "build_target",
    "calibrate",
    "default_sampler",
    "default_starts",
    "make_algebra",
    "sample",
]
