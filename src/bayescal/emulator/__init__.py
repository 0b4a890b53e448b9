"""Gaussian-process emulator on PCA weights: basis, kernel and likelihood algebra.

* :mod:`~bayescal.emulator.basis` -- standardisation, output PCA (GPMSA
  scaling), weights (eqs. 6, 13), the eq. 7 precision update, input PCA.
* :mod:`~bayescal.emulator.kernel` -- the separable covariance of eq. 8.
* :mod:`~bayescal.emulator.dense` -- dense Cholesky reference likelihoods.
* :mod:`~bayescal.emulator.kron` -- fast Kronecker likelihoods (the default).
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
from bayescal.emulator.dense import (
    DenseCalibrationDensity,
    GridData,
    dense_logpdf,
    dense_training_logpdf,
)
from bayescal.emulator.kernel import LogDensity, SeparableKernel, beta_to_rho, rho_to_beta
from bayescal.emulator.kron import (
    CalibrationAlgebra,
    KronCalibrationDensity,
    SymEig,
    kron_training_basis,
    kron_training_logpdf,
    make_algebra,
    training_logpdf,
)

__all__ = [
    "Basis",
    "CalibrationAlgebra",
    "DenseCalibrationDensity",
    "GridData",
    "InputPCA",
    "KronCalibrationDensity",
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
    "make_algebra",
    "pca_basis",
    "rho_to_beta",
    "stack_outputs",
    "standardise",
    "training_logpdf",
]
