"""Batched calibration likelihood: ``B`` points of eq. 12 at once (issue 7).

The arithmetic is that of the full-grid ``"schur"`` path of
:mod:`bayescal.emulator.kron` (``_Stacked``), with a leading axis of ``B``
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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from bayescal.emulator.kernel import LOG_2PI, FloatArray

BoolArray = NDArray[np.bool_]
Sims = tuple[FloatArray, FloatArray, BoolArray, FloatArray, FloatArray]
"""``(logdet (n,), quad (n,), ok (n,), inv_den (n, p, R, m*), h (n, p, R, m*))``."""


class _Cache(Protocol):
    """What :class:`BatchStacked` reads from one basis cache of ``kron``."""

    @property
    def beta_theta(self) -> FloatArray: ...
    @property
    def kernel(self) -> Any: ...
    @property
    def eig_theta(self) -> Any: ...
    @property
    def eig_x(self) -> Any: ...
    @property
    def w_rot(self) -> FloatArray: ...
    @property
    def obs_rot(self) -> FloatArray: ...


@dataclass(frozen=True)
class BatchStacked:
    """The fixed arrays of the full-grid ``"schur"`` path, stacked over bases.

    Attributes
    ----------
    theta
        Design ``(R, t)``, scaled to [0, 1]. [-]
    beta_theta
        ``-4 ln rho`` of the theta inputs per basis ``(t, p)``. [-]
    variance
        ``1 / tau`` per basis ``(p,)``. [-]
    q_t_trans
        Transposed eigenvectors ``Q_t^T`` of ``S_theta`` per basis ``(p, R, R)``. [-]
    l_t, l_x
        Eigenvalues of ``S_theta`` ``(p, R)`` and ``S_x`` ``(p, m*)``. [-]
    w_rot
        Rotated simulator weights ``Q_t^T W Q_x`` ``(p, R, m*)``. [-]
    obs_rot
        Rotated observed weights ``Q_x^T w*`` ``(p, m*)``. [-]
    """

    theta: FloatArray
    beta_theta: FloatArray
    variance: FloatArray
    q_t_trans: FloatArray
    l_t: FloatArray
    l_x: FloatArray
    w_rot: FloatArray
    obs_rot: FloatArray

    @classmethod
    def build(cls, theta: FloatArray, caches: Sequence[_Cache]) -> BatchStacked:
        """Stack the per-basis caches of :class:`~bayescal.emulator.kron.KronCalibrationDensity`."""
        return cls(
            theta=theta,
            beta_theta=np.stack([c.beta_theta for c in caches], axis=1),
            variance=np.array([float(c.kernel.variance) for c in caches]),
            q_t_trans=np.ascontiguousarray(np.stack([c.eig_theta.vectors.T for c in caches])),
            l_t=np.stack([c.eig_theta.values for c in caches]),
            l_x=np.stack([c.eig_x.values for c in caches]),
            w_rot=np.stack([c.w_rot for c in caches]),
            obs_rot=np.stack([c.obs_rot for c in caches]),
        )

    @cached_property
    def size(self) -> int:
        """Rows of the stacked vector ``[w; w*]`` summed over bases, ``p (R m* + m*)``."""
        p, n_runs, n_per = self.w_rot.shape
        return p * (n_runs * n_per + n_per)

    @cached_property
    def outer(self) -> FloatArray:
        """``l_t l_x^T`` per basis ``(p, R, m*)``."""
        return self.l_t[:, :, None] * self.l_x[:, None, :]

    @cached_property
    def outer_min(self) -> FloatArray:
        """Smallest entry of :attr:`outer` per basis ``(p,)``."""
        return self.outer.min(axis=(1, 2))

    def sims(self, a: FloatArray, out: tuple[FloatArray, FloatArray] | None = None) -> Sims:
        """Simulator blocks for nuggets ``a`` ``(n, p)``.

        Returns ``(logdet (n,), quad (n,), ok (n,), inv_den (n, p, R, m*),
        h (n, p, R, m*))``; ``ok`` is False where a block is not positive definite.
        ``out`` may give the two large arrays to write into (of that shape).
        """
        n = a.shape[0]
        shape = (n, *self.w_rot.shape)
        if out is None or out[0].shape != shape:
            out = (np.empty(shape), np.empty(shape))
        inv_den, h = out
        # min(fl(x + a)) = fl(min(x) + a): rounding is monotonic.
        ok: BoolArray = np.asarray(((self.outer_min[None, :] + a) > 0.0).all(axis=1))
        np.add(self.outer[None, :, :, :], a[:, :, None, None], out=inv_den)
        with np.errstate(invalid="ignore", divide="ignore"):
            logdet = np.log(inv_den.reshape(n, -1), out=h.reshape(n, -1)).sum(axis=1)
        np.reciprocal(inv_den, out=inv_den)
        np.multiply(self.w_rot, inv_den, out=h)
        quad = h.reshape(n, -1) @ self.w_rot.reshape(-1)
        return logdet, quad, ok, inv_den, h

    def c_hat(self, theta_star: FloatArray) -> FloatArray:
        """``Q_t^T c`` per point and basis ``(n, p, R)`` for ``theta*`` ``(n, t)``.

        One matrix-vector product per point and basis, as the scalar path does:
        a single matrix-matrix product over the points rounds differently, and
        the Schur complement (``l_x / tau + a* - g``, often 5 digits of
        cancellation) would turn that 1e-16 into 1e-11 differences between a
        batch and a loop of single evaluations.
        """
        diff = self.theta[None, :, :] - theta_star[:, None, :]
        c = np.exp(-((diff * diff) @ self.beta_theta)) * self.variance  # (n, R, p)
        out = np.matmul(self.q_t_trans[None, :, :, :], c.transpose(0, 2, 1)[:, :, :, None])
        result: FloatArray = out[:, :, :, 0]
        return result

    def u_g(
        self, c_hat: FloatArray, inv_den: FloatArray, h: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """``u`` and ``g`` of the ``kron`` module docstring, ``(n, p, m*)`` each."""
        u = np.matmul(c_hat[:, :, None, :], h)[:, :, 0, :]
        g = np.matmul((c_hat * c_hat)[:, :, None, :], inv_den)[:, :, 0, :]
        u *= self.l_x
        g *= self.l_x2
        return u, g

    @cached_property
    def var_lx(self) -> FloatArray:
        """``l_x / tau`` per basis ``(p, m*)``."""
        return self.variance[:, None] * self.l_x

    @cached_property
    def l_x2(self) -> FloatArray:
        """``l_x^2`` per basis ``(p, m*)``."""
        return self.l_x * self.l_x

    def finish(
        self, sims: Sims, u: FloatArray, g: FloatArray, a_star: FloatArray
    ) -> tuple[FloatArray, BoolArray]:
        """Log-densities ``(n,)`` and a mask of the points whose covariance is positive definite."""
        schur = self.var_lx + a_star[:, :, None]
        schur -= g
        ok = sims[2] & (schur.reshape(schur.shape[0], -1).min(axis=1) > 0.0)
        resid = self.obs_rot - u
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
        return -0.5 * (self.size * LOG_2PI + logdet + quad), ok


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
    stacked
        The fixed arrays.
    ktk
        ``k_j^T k_j``, ``(p,)``. [-]
    theta_star
        Calibration parameters ``(B, t)``, scaled to [0, 1]. [-]
    lam, lam_star
        Precisions ``(B,)``, > 0. [-]

    Attributes
    ----------
    values
        Log-likelihood of the current points ``(B,)``.
    ok
        Whether each current covariance is positive definite ``(B,)``.
    """

    def __init__(
        self,
        stacked: BatchStacked,
        ktk: FloatArray,
        theta_star: FloatArray,
        lam: FloatArray,
        lam_star: FloatArray,
    ) -> None:
        self.stacked, self.ktk = stacked, ktk
        self.theta_star = np.array(theta_star, dtype=float)
        self.lam = np.array(lam, dtype=float)
        self.a_star = _star_nuggets(ktk, np.asarray(lam_star, dtype=float))
        self.sims = stacked.sims(_nuggets(ktk, self.lam))
        self.c_hat = stacked.c_hat(self.theta_star)
        self.u, self.g = stacked.u_g(self.c_hat, self.sims[3], self.sims[4])
        self.values, self.ok = stacked.finish(self.sims, self.u, self.g, self.a_star)
        self._spare: tuple[FloatArray, FloatArray] | None = None
        self._pending: tuple[str, tuple[Any, ...]] = ("none", ())

    def propose_theta(self, theta_star: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Log-likelihoods ``(B,)`` and PD mask with ``theta*`` ``(B, t)`` moved."""
        ts = np.array(theta_star, dtype=float)
        c_hat = self.stacked.c_hat(ts)
        u, g = self.stacked.u_g(c_hat, self.sims[3], self.sims[4])
        self._pending = ("theta", (ts, c_hat, u, g))
        return self.stacked.finish(self.sims, u, g, self.a_star)

    def propose_lam(self, lam: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Log-likelihoods ``(B,)`` and PD mask with ``lambda`` ``(B,)`` moved."""
        lam_new = np.array(lam, dtype=float)
        sims = self.stacked.sims(_nuggets(self.ktk, lam_new), self._spare)
        self._spare = None
        u, g = self.stacked.u_g(self.c_hat, sims[3], sims[4])
        self._pending = ("lam", (lam_new, sims, u, g))
        return self.stacked.finish(sims, u, g, self.a_star)

    def propose_lam_star(self, lam_star: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Log-likelihoods ``(B,)`` and PD mask with ``lambda*`` ``(B,)`` moved."""
        a_star = _star_nuggets(self.ktk, np.asarray(lam_star, dtype=float))
        self._pending = ("lam_star", (a_star,))
        return self.stacked.finish(self.sims, self.u, self.g, a_star)

    def commit(self, accept: BoolArray, values: FloatArray, ok: BoolArray) -> None:
        """Make the last proposal current where ``accept``; its ``values`` and ``ok`` with it."""
        kind, parts = self._pending
        self._pending = ("none", ())
        rows = np.flatnonzero(accept)
        if kind == "lam":
            self._commit_lam(accept, rows, parts)
        elif rows.size and kind == "theta":
            ts, c_hat, u, g = parts
            for current, new in ((self.theta_star, ts), (self.c_hat, c_hat), (self.u, u)):
                current[rows] = new[rows]
            self.g[rows] = g[rows]
        elif rows.size and kind == "lam_star":
            self.a_star[rows] = parts[0][rows]
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
    stacked: BatchStacked,
    ktk: FloatArray,
    theta_star: FloatArray,
    lam: FloatArray,
    lam_star: FloatArray,
) -> tuple[FloatArray, BoolArray]:
    """Log-likelihoods ``(n,)`` of ``n`` points and which are positive definite (no memo)."""
    session = BatchSession(stacked, ktk, theta_star, lam, lam_star)
    return session.values, session.ok
