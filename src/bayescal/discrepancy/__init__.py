"""The difference process ``Delta(x)`` of the paper's eqs. 18–25.

``Delta = observation - model`` (``y* = f(theta*, x) + Delta(x) + eps``, eq. 18;
the paper's eq. 25 writes the opposite sign). Modules:

* :mod:`~bayescal.discrepancy.moments` -- the empirical moments of eq. 25 and
  the generalised least squares of eqs. 20–24 with each output's measurement
  error (standardised units);
* :mod:`~bayescal.discrepancy.phase` -- what stays fixed in the phase, the
  periodic update and the scalar target of theta* between updates;
* :mod:`~bayescal.discrepancy.batched` -- that target's likelihood (eq. 19) for
  all chains at once;
* :mod:`~bayescal.discrepancy.sampler` -- the chains: lockstep, whitened, as
  long as convergence needs, with checkpoints;
* :mod:`~bayescal.discrepancy.priors` -- priors of theta* from the calibration
  posterior (well identified: moment-matched Beta; piled up at a bound:
  Beta(1, 2));
* :mod:`~bayescal.discrepancy.delta_gp` -- PCA of ``Delta`` and one GP over ``x``
  per component, to predict ``Delta`` on new periods;
* :mod:`~bayescal.discrepancy.model` -- :func:`estimate_discrepancy` and
  :class:`Discrepancy` (physical units).

The netCDF artefact is :mod:`bayescal.store.discrepancy`.

::

    disc = estimate_discrepancy(emulator, assembled, posterior)
    mean, var = disc.predict(assembled.x_test)      # (N, m_test), physical units
"""

from bayescal.discrepancy.delta_gp import DeltaGP, fit_delta_gp
from bayescal.discrepancy.model import Discrepancy, estimate_discrepancy
from bayescal.discrepancy.priors import default_priors, piled_up

__all__ = [
    "DeltaGP",
    "Discrepancy",
    "default_priors",
    "estimate_discrepancy",
    "fit_delta_gp",
    "piled_up",
]
