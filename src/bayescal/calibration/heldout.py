"""The calibration likelihood without one period's measurements, on the full grid's fast route.

Leaving the measurements of period ``i`` out breaks the grid of runs x
periods (:mod:`bayescal.calibration.kron`): the general Schur route then
factorises an ``m* - 1`` block per basis and evaluation, several times slower
than the full grid. For one output with white errors (the paper's ``[u,
lambda, lambda*]``) there is an exact shortcut. Per basis the observed
weights given the simulator weights are Gaussian with the Schur complement
``S = Q_x diag(s) Q_x^T`` (``s = l_x / tau + a* - g``) and the residual
``r = Q_x (obs_rot - u)``; removing period ``i`` from a Gaussian leaves

    log N(w*_-i) = log N(w*) - log N(w*_i | w*_-i),
    w*_i | w*_-i ~ N(w*_i - z_i / P_ii, 1 / P_ii),

with ``P = S^-1 = Q_x diag(1/s) Q_x^T`` and ``z = S^-1 r = Q_x ((obs_rot - u) / s)``:
``O(m*)`` per basis on top of the full-grid likelihood, whose pieces (``u``,
``g``, ``a*``) :class:`~bayescal.calibration.batch.BatchSession` evaluates for
``B`` points at once. :class:`HeldOutAlgebra` offers this as a likelihood back
end for :class:`~bayescal.calibration.target.CalibrationPosterior`; it equals
the general route on the observed subset to rounding (tested).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from bayescal.calibration.batch import BatchErrors, BatchSession, check_batch_args, checked
from bayescal.calibration.grid import StackedGrid
from bayescal.calibration.kron import CalibrationAlgebra, KronCalibrationDensity
from bayescal.emulator.dense import GridData
from bayescal.emulator.kernel import LOG_2PI, FloatArray, LogDensity

__all__ = ["HeldOutAlgebra"]

#: Points per batch (keeps the ``(B, p, R, m*)`` work arrays of a session small).
CHUNK = 256


class HeldOutAlgebra:
    """Eq. 12 without the measurements of one period (one white output, full-grid route).

    Parameters
    ----------
    full
        The Kronecker density with every period observed (method ``"schur"``).
    period
        The period whose observed weights are left out.
    """

    def __init__(self, full: KronCalibrationDensity, period: int) -> None:
        grid = full.stacked_grid()
        m = grid.l_x.shape[1]
        if not grid.full_grid:
            raise ValueError("the held-out shortcut needs every period observed in `full`")
        if not 0 <= period < m:
            raise IndexError(f"period {period} is not one of the {m} training periods")
        self.full = full
        self.period = int(period)
        self._grid = grid
        self._q = np.stack([b.eig_x.vectors[period] for b in grid.bases])  # (p, m*)
        self._q2 = self._q * self._q

    @property
    def data(self) -> GridData:
        """The full density's fixed inputs (every period's observed weights)."""
        return self.full.data

    def stacked_grid(self) -> StackedGrid | None:
        """None: the JAX route has no held-out form."""
        return None

    def batch_session(
        self, theta_star: ArrayLike, lam: ArrayLike, lam_star: ArrayLike
    ) -> BatchSession | None:
        """None: lockstep chains call :meth:`logpdf_batch` for every proposal."""
        return None

    def logpdf(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> float:
        """Log-density of the simulator weights and the other periods' observed weights."""
        ts = np.asarray(theta_star, dtype=float).reshape(1, -1)
        lam_s = np.asarray(lam_star, dtype=float).reshape(1)
        out = self.logpdf_batch(ts, np.array([float(lam)]), lam_s)
        return float(out[0])

    def logpdf_batch(
        self,
        theta_star: ArrayLike,
        lam: ArrayLike,
        lam_star: ArrayLike,
        *,
        errors: BatchErrors = "raise",
    ) -> FloatArray:
        """:meth:`logpdf` at ``B`` points ``(B, t)``, ``(B,)``, ``(B,)``."""
        ts, lam_arr, lam_s = check_batch_args(self.data, theta_star, lam, lam_star, errors)
        values = np.empty(ts.shape[0])
        ok = np.empty(ts.shape[0], dtype=bool)
        for start in range(0, ts.shape[0], CHUNK):
            rows = slice(start, start + CHUNK)
            values[rows], ok[rows] = self._chunk(ts[rows], lam_arr[rows], lam_s[rows])
        return checked(values, ok, errors, ts, lam_arr, lam_s)

    def _chunk(
        self, ts: FloatArray, lam: FloatArray, lam_s: FloatArray
    ) -> tuple[FloatArray, np.ndarray]:
        grid = self._grid
        session = BatchSession(grid, ts, lam, lam_s)
        schur = grid.var_lx[None] + session.a_star[:, :, None] - session.g  # (B, p, m*)
        with np.errstate(invalid="ignore", divide="ignore"):
            inv = 1.0 / schur
            prec = np.einsum("jk,njk->nj", self._q2, inv)
            z = np.einsum("jk,njk->nj", self._q, (grid.obs_rot[None] - session.u) * inv)
            cond = -0.5 * (LOG_2PI - np.log(prec) + z * z / prec)
        ok = session.ok & np.all(np.isfinite(cond), axis=1)
        return np.where(ok, session.values - cond.sum(axis=1), -np.inf), ok

    # The grouped and per-nugget forms serve several outputs, AR(1) errors and the
    # discrepancy; those calibrations leave a period out by the general route.
    def pieces(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> LogDensity:
        """Not offered (only :meth:`logpdf`)."""
        raise NotImplementedError("the held-out shortcut offers logpdf only")

    def pieces_nuggets(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity:
        """Not offered (only :meth:`logpdf`)."""
        raise NotImplementedError("the held-out shortcut offers logpdf only")

    def pieces_grouped(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        groups: Sequence[tuple[Sequence[int], FloatArray]],
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity:
        """Not offered (only :meth:`logpdf`)."""
        raise NotImplementedError("the held-out shortcut offers logpdf only")

    def mean_gradient(self, theta_star: ArrayLike, a: ArrayLike) -> FloatArray:
        """Not offered (only :meth:`logpdf`)."""
        raise NotImplementedError("the held-out shortcut offers logpdf only")

    def with_observations(self, w_star: ArrayLike) -> CalibrationAlgebra:
        """Not offered: the observed weights of a plain output do not move."""
        raise NotImplementedError("the held-out shortcut keeps its observed weights")
