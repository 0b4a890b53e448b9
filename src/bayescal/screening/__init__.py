"""Sensitivity screening before calibration: Morris elementary effects (SALib).

:mod:`~bayescal.screening.morris` draws the trajectories on the unit cube of
the parameters' prior ranges, computes mu*, mu and sigma of each parameter
for each output with bootstrap confidence intervals of mu*, and proposes the
parameters to calibrate. Numerical only: the runs go through
:func:`bayescal.runner.run_design` (:mod:`bayescal.pipeline.screen`), and the
files and the page are written by :mod:`bayescal.store.screening` and
:mod:`bayescal.report.screening`.
"""

from bayescal.screening.morris import (
    MorrisDesign,
    MorrisIndices,
    Proposal,
    morris_design,
    morris_indices,
    propose,
)

__all__ = [
    "MorrisDesign",
    "MorrisIndices",
    "Proposal",
    "morris_design",
    "morris_indices",
    "propose",
]
