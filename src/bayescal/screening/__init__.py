"""Sensitivity screening before calibration: Morris elementary effects or Sobol indices.

:mod:`~bayescal.screening.morris` draws the trajectories on the unit cube of
the parameters' prior ranges, computes mu*, mu and sigma of each parameter
for each output with bootstrap confidence intervals of mu*;
:mod:`~bayescal.screening.sobol` fits a quick GP
(:mod:`~bayescal.screening.surrogate`) to the runs of a Latin hypercube and
computes the first-order and total Sobol indices of each parameter on it,
with intervals that hold the GP's uncertainty; :mod:`~bayescal.screening.proposal`
proposes the parameters to calibrate from either. Numerical only: the runs
go through :func:`bayescal.runner.run_design` (:mod:`bayescal.pipeline.screen`),
and the files and the page are written by :mod:`bayescal.store.screening` and
:mod:`bayescal.report.screening`.
"""

from bayescal.screening.morris import (
    MorrisDesign,
    MorrisIndices,
    morris_design,
    morris_indices,
)
from bayescal.screening.proposal import Proposal, propose
from bayescal.screening.sobol import Q2_WARN, SobolIndices, sobol_indices
from bayescal.screening.surrogate import ScalarGP, fit_scalar_gp

__all__ = [
    "Q2_WARN",
    "MorrisDesign",
    "MorrisIndices",
    "Proposal",
    "ScalarGP",
    "SobolIndices",
    "fit_scalar_gp",
    "morris_design",
    "morris_indices",
    "propose",
    "sobol_indices",
]
