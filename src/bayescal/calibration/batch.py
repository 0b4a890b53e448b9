"""Batched calibration likelihood: ``B`` points of eq. 12 at once, for chains in lockstep.

The arithmetic is that of the full-grid ``"schur"`` route of
:mod:`bayescal.calibration.kron`, on the same fixed arrays
(:class:`~bayescal.calibration.grid.StackedGrid`), with a leading axis of ``B``
points (one per chain of a lockstep sampler): for point ``n`` and basis ``j``

* simulator block (moves with ``lambda`` only): ``den = l_t l_x^T + a_nj``,
  ``log |A| = sum log den``, ``h = Wt / den``, ``w^T A^-1 w = sum h Wt``;
* rotated kernel vector (moves with ``theta*`` only): ``c_hat = Q_t^T c``;
* ``u = l_x (c_hat^T h)``, ``g = l_x^2 ((c_hat^2)^T / den)`` (both);
* the diagonal Schur complement ``l_x / tau + a*_nj - g`` and its residual.

The per-point arithmetic is that of one scalar evaluation, with the same
BLAS calls per point, so a batch equals a loop of scalar evaluations to
rounding (~1e-15 relative); what the batch removes is the Python overhead of
``B`` calls (about 30 small numpy calls each), which dominates at the
paper's size (R = 30, m* = 25).

:class:`BatchSession` is the sampler's form: it holds the pieces of the
current point of every chain, evaluates proposals that move ``theta*``,
``lambda`` or ``lambda*`` of every chain (recomputing only what that move
changes, as the memos of the scalar path do), and takes over the rows a
Metropolis step accepted (:meth:`BatchSession.commit`).

:class:`~bayescal.calibration.target.BatchedPosterior` adds the priors and
offers the whole log posterior of eq. 16 to chains in lockstep.
"""

from __future__ import annotations

from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.calibration.grid import StackedGrid
from bayescal.emulator.dense import GridData
from bayescal.emulator.kernel import LOG_2PI, FloatArray

__all__ = [
    "BatchErrors",
    "BatchSession",
    "batch_logpdf",
    "check_batch_args",
    "checked",
    "logpdf_loop",
]

BoolArray = NDArray[np.bool_]
BatchErrors = Literal["raise", "-inf"]
Sims = tuple[FloatArray, FloatArray, BoolArray, FloatArray, FloatArray]
"""``(logdet (n,), quad (n,), ok (n,), inv_den (n, p, R, m*), h (n, p, R, m*))``."""
_INF = float("inf")


def _sims(
    grid: StackedGrid, a: FloatArray, out: tuple[FloatArray, FloatArray] | None = None
) -> Sims:
    """Simulator blocks for nuggets ``a`` ``(n, p)``.

    Returns ``(logdet (n,), quad (n,), ok (n,), inv_den (n, p, R, m*),
    h (n, p, R, m*))``; ``ok`` is False where a block is not positive definite.
    ``out`` may give the two large arrays to write into (of that shape).
    """
    n = a.shape[0]
    shape = (n, *grid.w_rot.shape)
    if out is None or out[0].shape != shape:
        out = (np.empty(shape), np.empty(shape))
    inv_den, h = out
    # min(fl(x + a)) = fl(min(x) + a): rounding is monotonic.
    ok: BoolArray = np.asarray(((grid.outer_min[None, :] + a) > 0.0).all(axis=1))
    np.add(grid.outer[None, :, :, :], a[:, :, None, None], out=inv_den)
    with np.errstate(invalid="ignore", divide="ignore"):
        logdet = np.log(inv_den.reshape(n, -1), out=h.reshape(n, -1)).sum(axis=1)
    np.reciprocal(inv_den, out=inv_den)
    np.multiply(grid.w_rot, inv_den, out=h)
    quad = h.reshape(n, -1) @ grid.w_rot.reshape(-1)
    return logdet, quad, ok, inv_den, h


def _c_hat(grid: StackedGrid, theta_star: FloatArray) -> FloatArray:
    """``Q_t^T c`` per point and basis ``(n, p, R)`` for ``theta*`` ``(n, t)``.

    One matrix-vector product per point and basis, as the scalar path does:
    a single matrix-matrix product over the points rounds differently, and
    the Schur complement (``l_x / tau + a* - g``, often 5 digits of
    cancellation) would turn that 1e-16 into 1e-11 differences between a
    batch and a loop of single evaluations.
    """
    diff = grid.theta[None, :, :] - theta_star[:, None, :]
    c = np.exp(-((diff * diff) @ grid.beta_theta)) * grid.variance  # (n, R, p)
    out = np.matmul(grid.q_t_trans[None, :, :, :], c.transpose(0, 2, 1)[:, :, :, None])
    result: FloatArray = out[:, :, :, 0]
    return result


def _u_g(
    grid: StackedGrid, c_hat: FloatArray, inv_den: FloatArray, h: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``u`` and ``g`` of the ``kron`` module docstring, ``(n, p, m*)`` each."""
    u = np.matmul(c_hat[:, :, None, :], h)[:, :, 0, :]
    g = np.matmul((c_hat * c_hat)[:, :, None, :], inv_den)[:, :, 0, :]
    u *= grid.l_x
    g *= grid.l_x2
    return u, g


def _finish(
    grid: StackedGrid, sims: Sims, u: FloatArray, g: FloatArray, a_star: FloatArray
) -> tuple[FloatArray, BoolArray]:
    """Log-densities ``(n,)`` and a mask of the points whose covariance is positive definite."""
    schur = grid.var_lx + a_star[:, :, None]
    schur -= g
    ok = sims[2] & (schur.reshape(schur.shape[0], -1).min(axis=1) > 0.0)
    resid = grid.obs_rot - u
    if ok.all():
        terms = resid / schur
        np.log(schur, out=schur)
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            terms = resid / schur
            np.log(schur, out=schur)
    terms *= resid
    logdet = sims[0] + schur.sum(axis=(1, 2))
    quad = sims[1] + terms.sum(axis=(1, 2))
    return -0.5 * (grid.size * LOG_2PI + logdet + quad), ok


def _nuggets(ktk: FloatArray, lam: FloatArray) -> FloatArray:
    """``(lambda_n k_j^T k_j)^-1``, ``(n, p)``, the float operations of ``kron``."""
    out: FloatArray = 1.0 / (lam[:, None] * ktk[None, :])
    return out


def _star_nuggets(ktk: FloatArray, lam_star: FloatArray) -> FloatArray:
    """``(k_j^T k_j lambda*_n)^-1``, ``(n, p)``, the float operations of ``kron``."""
    out: FloatArray = 1.0 / (ktk[None, :] * lam_star[:, None])
    return out


class BatchSession:
    """The current points of ``B`` chains and proposals that move one group of coordinates.

    Parameters
    ----------
    grid
        The fixed arrays of eq. 16.
    theta_star
        Calibration parameters ``(B, t)``, scaled to [0, 1]. [-]
    lam, lam_star
        Precisions ``(B,)``, > 0. [-]

    Attributes
    ----------
    theta_star, lam, lam_star
        The current points ``(B, t)``, ``(B,)``, ``(B,)``.
    values
        Log-likelihood of the current points ``(B,)``.
    ok
        Whether each current covariance is positive definite ``(B,)``.
    """

    def __init__(
        self,
        grid: StackedGrid,
        theta_star: FloatArray,
        lam: FloatArray,
        lam_star: FloatArray,
    ) -> None:
        self.grid, ktk = grid, grid.ktk
        self.theta_star = np.array(theta_star, dtype=float)
        self.lam = np.array(lam, dtype=float)
        self.lam_star = np.array(lam_star, dtype=float)
        self.a_star = _star_nuggets(ktk, self.lam_star)
        self.sims = _sims(grid, _nuggets(ktk, self.lam))
        self.c_hat = _c_hat(grid, self.theta_star)
        self.u, self.g = _u_g(grid, self.c_hat, self.sims[3], self.sims[4])
        self.values, self.ok = _finish(grid, self.sims, self.u, self.g, self.a_star)
        self._spare: tuple[FloatArray, FloatArray] | None = None
        self._pending: tuple[str, tuple[Any, ...], tuple[FloatArray, BoolArray] | None] = (
            "none",
            (),
            None,
        )

    def propose_theta(self, theta_star: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Log-likelihoods ``(B,)`` and PD mask with ``theta*`` ``(B, t)`` moved."""
        ts = np.array(theta_star, dtype=float)
        c_hat = _c_hat(self.grid, ts)
        u, g = _u_g(self.grid, c_hat, self.sims[3], self.sims[4])
        return self._propose("theta", (ts, c_hat, u, g), self.sims, u, g, self.a_star)

    def propose_lam(self, lam: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Log-likelihoods ``(B,)`` and PD mask with ``lambda`` ``(B,)`` moved."""
        lam_new = np.array(lam, dtype=float)
        sims = _sims(self.grid, _nuggets(self.grid.ktk, lam_new), self._spare)
        self._spare = None
        u, g = _u_g(self.grid, self.c_hat, sims[3], sims[4])
        return self._propose("lam", (lam_new, sims, u, g), sims, u, g, self.a_star)

    def propose_lam_star(self, lam_star: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Log-likelihoods ``(B,)`` and PD mask with ``lambda*`` ``(B,)`` moved."""
        lam_s = np.array(lam_star, dtype=float)
        a_star = _star_nuggets(self.grid.ktk, lam_s)
        return self._propose("lam_star", (lam_s, a_star), self.sims, self.u, self.g, a_star)

    def _propose(
        self,
        kind: str,
        parts: tuple[Any, ...],
        sims: Sims,
        u: FloatArray,
        g: FloatArray,
        a_star: FloatArray,
    ) -> tuple[FloatArray, BoolArray]:
        result = _finish(self.grid, sims, u, g, a_star)
        self._pending = (kind, parts, result)
        return result

    def commit(self, accept: BoolArray) -> None:
        """Make the last proposal current where ``accept`` (with its values)."""
        kind, parts, result = self._pending
        self._pending = ("none", (), None)
        rows = np.flatnonzero(accept)
        if result is None:
            if rows.size:
                raise RuntimeError("commit without a proposal")
            return
        values, ok = result
        if kind == "lam":
            self._commit_lam(accept, rows, parts)
        elif rows.size and kind == "theta":
            ts, c_hat, u, g = parts
            for current, new in ((self.theta_star, ts), (self.c_hat, c_hat), (self.u, u)):
                current[rows] = new[rows]
            self.g[rows] = g[rows]
        elif rows.size and kind == "lam_star":
            self.lam_star[rows] = parts[0][rows]
            self.a_star[rows] = parts[1][rows]
        if rows.size:
            self.values[rows] = values[rows]
            self.ok[rows] = ok[rows]

    def _commit_lam(
        self, accept: BoolArray, rows: NDArray[np.intp], parts: tuple[Any, ...]
    ) -> None:
        lam, sims, u, g = parts
        if rows.size * 2 > accept.size:
            # Most chains moved: adopt the proposal's arrays, copy the others back.
            keep = np.flatnonzero(~accept)
            for new, old in zip(sims, self.sims, strict=True):
                new[keep] = old[keep]
            for new, old in ((lam, self.lam), (u, self.u), (g, self.g)):
                new[keep] = old[keep]
            self._spare = (self.sims[3], self.sims[4])
            self.sims, self.lam, self.u, self.g = sims, lam, u, g
            return
        for current, new in zip(self.sims, sims, strict=True):
            current[rows] = new[rows]
        for current, new in ((self.lam, lam), (self.u, u), (self.g, g)):
            current[rows] = new[rows]
        self._spare = (sims[3], sims[4])


def batch_logpdf(
    grid: StackedGrid,
    theta_star: FloatArray,
    lam: FloatArray,
    lam_star: FloatArray,
) -> tuple[FloatArray, BoolArray]:
    """Log-likelihoods ``(n,)`` of ``n`` points and which are positive definite (no memo)."""
    session = BatchSession(grid, theta_star, lam, lam_star)
    return session.values, session.ok


def check_batch_args(
    data: GridData,
    theta_star: ArrayLike,
    lam: ArrayLike,
    lam_star: ArrayLike,
    errors: str = "raise",
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validated ``theta*`` ``(B, t)``, ``lambda`` ``(B,)`` and ``lambda*`` ``(B,)``."""
    if errors not in ("raise", "-inf"):
        raise ValueError(f"errors must be 'raise' or '-inf', got {errors!r}")
    t = data.theta.shape[1]
    ts = np.ascontiguousarray(theta_star, dtype=float)
    lam_arr = np.ascontiguousarray(lam, dtype=float)
    lam_s = np.ascontiguousarray(lam_star, dtype=float)
    n = ts.shape[0] if ts.ndim == 2 else -1
    if ts.ndim != 2 or ts.shape[1] != t or lam_arr.shape != (n,) or lam_s.shape != (n,):
        raise ValueError(
            f"expected theta_star (B, {t}), lam (B,) and lam_star (B,), got "
            f"{ts.shape}, {lam_arr.shape} and {lam_s.shape}"
        )
    if not min(lam_arr.min(initial=np.inf), lam_s.min(initial=np.inf)) > 0.0:
        raise ValueError("precisions lambda and lambda* must be > 0")
    return ts, lam_arr, lam_s


class _PointDensity(Protocol):
    def logpdf(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> float: ...


def logpdf_loop(
    algebra: _PointDensity,
    ts: FloatArray,
    lam: FloatArray,
    lam_s: FloatArray,
    errors: BatchErrors,
) -> FloatArray:
    """``algebra.logpdf`` point by point (a back end without a batched form)."""
    out = np.empty(ts.shape[0])
    for n in range(ts.shape[0]):
        try:
            out[n] = algebra.logpdf(ts[n], float(lam[n]), float(lam_s[n]))
        except np.linalg.LinAlgError:
            if errors == "raise":
                raise
            out[n] = -np.inf
    return out


def checked(
    values: FloatArray,
    ok: BoolArray,
    errors: BatchErrors,
    ts: FloatArray,
    lam: FloatArray,
    lam_s: FloatArray,
) -> FloatArray:
    """``values`` with ``-inf`` where not positive definite, or raise (``errors``)."""
    if ok.all():
        return values
    bad = int(np.flatnonzero(~ok)[0])
    if errors == "raise":
        raise np.linalg.LinAlgError(
            f"covariance of point {bad} (theta* = {ts[bad].tolist()}, lambda = "
            f"{lam[bad]:.6g}, lambda* = {lam_s[bad]:.6g}) is not positive definite"
        )
    out: FloatArray = np.where(ok, values, -np.inf)
    return out
