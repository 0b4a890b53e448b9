"""Gaussian-process emulator on PCA weights: basis, kernel, likelihood algebra, training.

* :mod:`~bayescal.emulator.basis` -- standardisation, output PCA (GPMSA
  scaling), weights (eqs. 6, 13), the eq. 7 precision update, input PCA.
* :mod:`~bayescal.emulator.assemble` -- periods cut, standardised and projected.
* :mod:`~bayescal.emulator.kernel` -- the separable covariance of eq. 8.
* :mod:`~bayescal.emulator.dense` -- dense Cholesky reference likelihoods.
* :mod:`~bayescal.emulator.kron` -- fast Kronecker training likelihood (eqs. 5, 10).
* :mod:`~bayescal.emulator.gradient` -- eq. 9 on the log scale with its exact gradient.
* :mod:`~bayescal.emulator.mapfit` -- the MAP by multi-start L-BFGS-B, Laplace approximation.
* :mod:`~bayescal.emulator.training` -- the hyperparameter posterior (eq. 9), training
  (gradient MAP search by default, or the paper's MCMC).
* :mod:`~bayescal.emulator.gp` -- the trained emulator: prediction, leave-one-run-out CV.

The calibration likelihood (eqs. 12-16) is in :mod:`bayescal.calibration`.
"""

from bayescal.emulator.basis import (
    Basis,
    InputPCA,
    Normaliser,
    SeriesPCA,
    Standardisation,
    input_pca,
    pca_basis,
    stack_outputs,
    standardise,
)
from bayescal.emulator.dense import GridData, dense_logpdf, dense_training_logpdf
from bayescal.emulator.kernel import LogDensity, SeparableKernel, beta_to_rho, rho_to_beta
from bayescal.emulator.kron import (
    SymEig,
    kron_training_basis,
    kron_training_logpdf,
    training_logpdf,
)

__all__ = [
    "Basis",
    "GridData",
    "InputPCA",
    "LogDensity",
    "Normaliser",
    "SeparableKernel",
    "SeriesPCA",
    "Standardisation",
    "SymEig",
    "beta_to_rho",
    "dense_logpdf",
    "dense_training_logpdf",
    "input_pca",
    "kron_training_basis",
    "kron_training_logpdf",
    "pca_basis",
    "rho_to_beta",
    "stack_outputs",
    "standardise",
    "training_logpdf",
]
