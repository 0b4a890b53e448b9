"""Calibration likelihood of eq. 12 (hyperparameters fixed) by the Kronecker structure.

The simulator block of basis ``j`` is ``A = S_theta ⊗ S_x + a I`` on the grid
of ``R`` runs x ``m*`` periods (see :mod:`bayescal.emulator.kron` for its
log-determinant and quadratic form from the two small eigen-decompositions).
Calibration appends the observed rows ``[theta*, x_i]``. Two exact ways:

``"schur"`` (default)
    Partition ``Omega = [[A, B], [B^T, C]]`` with ``B = c ⊗ S_x[:, O]``
    (``c = S_theta(theta, theta*)``) and ``C = tau^-1 S_x[O, O] + diag(a*)``.
    In the rotated basis ``B^T A^-1 B = P diag(g) P^T`` and ``B^T A^-1 w = P u``
    with ``P = Q_x[O, :]``, ``c_hat = Q_t^T c``,
    ``g_i = l_i^2 sum_k c_hat_k^2 / (l_k l_i + a)`` and
    ``u_i = l_i sum_k c_hat_k Wt_ki / (l_k l_i + a)``. The Schur complement
    ``S = C - P diag(g) P^T`` gives ``log |Omega| = log |A| + log |S|`` and
    ``v^T Omega^-1 v = w^T A^-1 w + r^T S^-1 r`` with ``r = w* - P u``. When every
    period is observed and ``a*`` is uniform, ``S = Q_x diag(l_i / tau + a* - g_i)
    Q_x^T`` is diagonal in the rotated basis: a likelihood costs
    ``O(R^2 + R m*)`` once ``Q_t, L_t, Q_x, L_x, Wt`` are stored. Otherwise
    (periods missing, per-period nuggets ``B_j``) ``S`` is an ``m_obs x m_obs``
    Cholesky, ``O(m_obs^3 + m_obs^2 m*)`` -- never a factorisation of ``Omega``.

``"eigen"``
    The construction of method.md: the observed row is an (R+1)-th theta row,
    ``Omega = S'_theta ⊗ S_x + diag(d) ⊗ I`` with ``d = [a, ..., a, a*]``;
    ``(D^-1/2 ⊗ I) Omega (D^-1/2 ⊗ I) = M ⊗ S_x + I`` with
    ``M = D^-1/2 S'_theta D^-1/2``, so with ``M = Q_m L_m Q_m^T``:
    ``log |Omega| = m* sum log d + sum log(l_m l_i + 1)``. Only for a full grid
    with uniform ``a*``; ``O(R^3 + R^2 m*)`` per likelihood (an ``(R+1)``
    eigen-decomposition each time theta* moves).

In both, what does not move with ``theta*``, ``lambda`` or ``lambda*`` is
computed once at construction (:class:`~bayescal.calibration.grid.StackedGrid`).
``"schur"`` is the default although method.md describes ``"eigen"``: it is
exact too, needs no eigen-decomposition per evaluation, covers the broken-grid
cases with the same code, and in 40-digit (mpmath) checks on small
ill-conditioned problems its error was below that of the dense Cholesky
reference.

Three evaluations share one set of fixed arrays,
:class:`~bayescal.calibration.grid.StackedGrid`: this module (one point, with
memos of what a Gibbs sweep leaves unchanged), :mod:`bayescal.calibration.batch`
(``B`` points for chains in lockstep) and :mod:`bayescal.calibration.hmc` (JAX).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import linalg
from scipy.linalg import lapack

from bayescal.calibration.batch import (
    BatchErrors,
    BatchSession,
    batch_logpdf,
    check_batch_args,
    checked,
    logpdf_loop,
)
from bayescal.calibration.dense import DenseCalibrationDensity
from bayescal.calibration.grid import BasisPieces, StackedGrid
from bayescal.calibration.orthogonal import Woodbury, rotated_gradient
from bayescal.emulator.dense import GridData, broadcast_obs_nuggets
from bayescal.emulator.kernel import FloatArray, LogDensity, SeparableKernel
from bayescal.emulator.kron import Lru, SymEig, positive_log_sum

__all__ = ["CalibrationAlgebra", "Kind", "KronCalibrationDensity", "make_algebra"]

Method = Literal["schur", "eigen"]
#: The memo attributes of :class:`KronCalibrationDensity` (not pickled).
_MEMOS = ("_sim_memo", "_c_hat_memo", "_u_g_memo", "_overlaps", "_sims_memo")


@dataclass(frozen=True)
class _SimBlock:
    """The parts of one basis that depend on the simulator nugget ``a`` only."""

    a: float
    logdet: float  # log |A|
    quad: float  # w^T A^-1 w
    inv_den: FloatArray  # 1 / (l_k l_i + a), R x m*
    h: FloatArray  # Wt / (l_k l_i + a), R x m*


def _sim_block(cache: BasisPieces, a: float) -> _SimBlock:
    den = np.multiply.outer(cache.eig_theta.values, cache.eig_x.values)
    den += a
    logdet = positive_log_sum(den, "simulator covariance")
    inv_den = np.reciprocal(den, out=den)
    h = cache.w_rot * inv_den
    return _SimBlock(a, logdet, float(np.vdot(h, cache.w_rot)), inv_den, h)


def _schur_basis(
    cache: BasisPieces,
    sim: _SimBlock,
    c: FloatArray,
    a_star: FloatArray,
    full_grid: bool,
    delta: float = 0.0,
    acc: tuple[Woodbury, int] | None = None,
) -> LogDensity:
    """One basis by the Schur complement of the Kronecker simulator block.

    ``delta`` adds ``delta S_x[O, O]`` to the observed block: a discrepancy
    ``GP(0, delta c_x)`` over the periods' conditions; ``acc`` gathers the
    orthogonal constraint's pieces of this basis (:mod:`~bayescal.calibration.orthogonal`).
    """
    lx = cache.eig_x.values
    logdet, quad = sim.logdet, sim.quad
    c_hat = cache.eig_theta.vectors.T @ c
    u = lx * (c_hat @ sim.h)
    g = lx * lx * ((c_hat * c_hat) @ sim.inv_den)
    size = sim.h.size + a_star.size
    variance = cache.kernel.variance + delta
    if full_grid and a_star.min() == a_star.max() and acc is None:
        schur = variance * lx + a_star[0] - g
        resid = cache.obs_rot - u
        logdet += positive_log_sum(schur, "observed-block Schur complement")
        return LogDensity.from_pieces(logdet, quad + float(np.vdot(resid, resid / schur)), size)
    p_obs = cache.p_obs
    schur_mat = variance * cache.sx_obs - (p_obs * g) @ p_obs.T
    schur_mat[np.diag_indices_from(schur_mat)] += a_star
    resid = cache.obs - p_obs @ u
    try:
        chol = linalg.cholesky(schur_mat, lower=True, check_finite=False)
    except np.linalg.LinAlgError as exc:
        raise np.linalg.LinAlgError(
            "observed-block Schur complement is not positive definite"
        ) from exc
    half = linalg.solve_triangular(chol, resid, lower=True, check_finite=False)
    logdet += 2.0 * float(np.sum(np.log(np.diag(chol))))
    if acc is not None:
        acc[0].factored([acc[1]], chol, half, rotated=False)
    return LogDensity.from_pieces(logdet, quad + float(half @ half), size)


def _grouped_bases(
    caches: Sequence[BasisPieces],
    sims: Sequence[_SimBlock],
    cs: Sequence[FloatArray],
    noise: FloatArray,
    deltas: Sequence[float],
    acc: tuple[Woodbury, list[int]] | None = None,
) -> LogDensity:
    """Bases whose observed weights share a noise block, by one joint Schur complement.

    The observed block of the ``q`` bases (rows basis-major: basis ``j``,
    period ``i``) is ``blockdiag_j(tau_j^-1 S_x,j[O, O]) + noise ⊗ I_m_obs``: the
    GP is independent between bases, the noise of a period's weights is not
    (AR(1) errors, :mod:`bayescal.emulator.noise`). Each basis's simulator
    block stays Kronecker; the ``(q m_obs)``-row Schur complement is factorised.
    """
    logdet = quad = 0.0
    m_obs = caches[0].obs.size
    q = len(caches)
    schur = np.kron(noise, np.eye(m_obs))
    resid = np.empty(q * m_obs)
    size = 0
    for j, (cache, sim, c, delta) in enumerate(zip(caches, sims, cs, deltas, strict=True)):
        lx = cache.eig_x.values
        c_hat = cache.eig_theta.vectors.T @ c
        u = lx * (c_hat @ sim.h)
        g = lx * lx * ((c_hat * c_hat) @ sim.inv_den)
        rows = slice(j * m_obs, (j + 1) * m_obs)
        p_obs = cache.p_obs
        variance = cache.kernel.variance + delta
        schur[rows, rows] += variance * cache.sx_obs - (p_obs * g) @ p_obs.T
        resid[rows] = cache.obs - p_obs @ u
        logdet += sim.logdet
        quad += sim.quad
        size += sim.h.size + m_obs
    try:
        chol = linalg.cholesky(schur, lower=True, check_finite=False)
    except np.linalg.LinAlgError as exc:
        raise np.linalg.LinAlgError(
            "observed-block Schur complement is not positive definite"
        ) from exc
    half = linalg.solve_triangular(chol, resid, lower=True, check_finite=False)
    logdet += 2.0 * float(np.sum(np.log(np.diag(chol))))
    if acc is not None:
        acc[0].factored(acc[1], chol, half, rotated=False)
    return LogDensity.from_pieces(logdet, quad + float(half @ half), size)


def _finish_grouped(
    grid: StackedGrid,
    sims: Sequence[_SimBlock],
    u: FloatArray,
    g: FloatArray,
    a_star: FloatArray,
    groups: Sequence[tuple[list[int], FloatArray, FloatArray]],
    delta: FloatArray,
    acc: Woodbury | None = None,
) -> LogDensity:
    """:func:`_finish` where some bases' observed weights share a noise block (full grid).

    In the rotated bases ``z_j = Q_x,j^T w*_j`` a basis's Schur complement is
    diagonal, ``(tau_j^-1 + delta_j) l_x,j + a*_j - g_j``; a group's noise ``N ⊗ I``
    becomes the blocks ``N_jk Q_x,j^T Q_x,k`` (``overlap``, fixed), so the group's
    ``(q m*)``-row matrix is those blocks plus the diagonal: the block-orthogonal
    rotation leaves its log-determinant and quadratic form as they were.
    ``groups``: ``(bases, noise (q, q), overlap (q, m*, q, m*))``.
    """
    variance = grid.variance + delta
    logdet = sum(sim.logdet for sim in sims)
    quad = sum(sim.quad for sim in sims)
    size = sum(sim.h.size for sim in sims) + grid.obs_rot.size
    free = np.ones(grid.n_bases, dtype=bool)
    for idx, _, _ in groups:
        free[idx] = False
    if free.any():
        part = _diagonal_schur(
            variance[free],
            grid.l_x[free],
            a_star[free],
            g[free],
            grid.obs_rot[free] - u[free],
            None if acc is None else (acc, np.flatnonzero(free)),
        )
        logdet += part[0]
        quad += part[1]
    for idx, noise, overlap in groups:
        q, m = len(idx), grid.l_x.shape[1]
        mat = (noise[:, None, :, None] * overlap).reshape(q * m, q * m)
        mat.flat[:: q * m + 1] += (variance[idx, None] * grid.l_x[idx] - g[idx]).ravel()
        # LAPACK directly: at a few hundred rows scipy's checking wrappers cost as much
        # as the factorisation
        chol, info = lapack.dpotrf(mat, lower=1, clean=0, overwrite_a=1)
        if info != 0:
            raise np.linalg.LinAlgError("observed-block Schur complement is not positive definite")
        resid = (grid.obs_rot[idx] - u[idx]).ravel()
        half = lapack.dtrtrs(chol, resid, lower=1)[0]
        logdet += 2.0 * float(np.sum(np.log(chol.flat[:: q * m + 1])))
        quad += float(half @ half)
        if acc is not None:
            acc.factored(idx, chol, half, rotated=True)
    return LogDensity.from_pieces(logdet, quad, size)


def _eigen_basis(cache: BasisPieces, c: FloatArray, a: float, a_star: float) -> LogDensity:
    """One basis by the scaled (R+1)-row theta matrix (full grid, uniform a*)."""
    n_runs = c.size
    s_prime = np.empty((n_runs + 1, n_runs + 1))
    s_prime[:n_runs, :n_runs] = cache.s_theta
    s_prime[:n_runs, n_runs] = c
    s_prime[n_runs, :n_runs] = c
    s_prime[n_runs, n_runs] = cache.kernel.variance
    d = np.full(n_runs + 1, a)
    d[n_runs] = a_star
    scale = 1.0 / np.sqrt(d)
    eig_m = SymEig.of(s_prime * np.multiply.outer(scale, scale))
    v_x = np.vstack([cache.w_x, cache.obs_rot[None, :]]) * scale[:, None]
    rot = eig_m.vectors.T @ v_x
    lam = np.multiply.outer(eig_m.values, cache.eig_x.values) + 1.0
    n_per = cache.eig_x.values.size
    logdet = n_per * float(np.sum(np.log(d))) + positive_log_sum(lam, "scaled covariance")
    return LogDensity.from_pieces(logdet, float(np.sum(rot * rot / lam)), lam.size)


def _c_hat(grid: StackedGrid, theta_star: FloatArray) -> FloatArray:
    """``Q_t^T c`` per basis ``(p, R)``: the only thing that moves with theta*."""
    c = grid.kernel_vector(theta_star)  # (R, p)
    return np.matmul(grid.q_t_trans, c.T[:, :, None])[:, :, 0]


def _u_g(
    grid: StackedGrid, c_hat: FloatArray, sims: Sequence[_SimBlock]
) -> tuple[FloatArray, FloatArray]:
    """``u`` and ``g`` of the module docstring, ``(p, m*)`` each (full grid, one point)."""
    u = np.empty_like(grid.l_x)
    g = np.empty_like(grid.l_x)
    for j, sim in enumerate(sims):
        row = c_hat[j]
        u[j] = row @ sim.h
        g[j] = (row * row) @ sim.inv_den
    u *= grid.l_x
    g *= grid.l_x * grid.l_x
    return u, g


def _finish(
    grid: StackedGrid,
    sims: Sequence[_SimBlock],
    u: FloatArray,
    g: FloatArray,
    a_star: FloatArray,
    delta: FloatArray | None = None,
    acc: Woodbury | None = None,
) -> LogDensity:
    """Add the observed block's Schur complement (diagonal in the rotated basis)."""
    variance = grid.variance if delta is None else grid.variance + delta
    everything = None if acc is None else (acc, np.arange(grid.n_bases))
    logdet, quad = _diagonal_schur(variance, grid.l_x, a_star, g, grid.obs_rot - u, everything)
    logdet += sum(sim.logdet for sim in sims)
    quad += sum(sim.quad for sim in sims)
    size = sum(sim.h.size for sim in sims) + grid.obs_rot.size
    return LogDensity.from_pieces(logdet, quad, size)


def _diagonal_schur(
    variance: FloatArray,
    l_x: FloatArray,
    a_star: FloatArray,
    g: FloatArray,
    resid: FloatArray,
    acc: tuple[Woodbury, NDArray[np.intp]] | None = None,
) -> tuple[float, float]:
    """Log-determinant and quadratic form of bases whose Schur complement is diagonal.

    In the rotated bases (full grid, white noise) basis ``j``'s observed block is
    ``(tau_j^-1 + delta_j) l_x,j + a*_j - g_j``; ``resid`` is ``z_j - u_j``;
    ``acc`` gathers the orthogonal constraint's pieces of these bases.
    """
    schur = variance[:, None] * l_x
    schur += a_star[:, None]
    schur -= g
    if acc is not None:
        acc[0].diagonal(list(acc[1]), schur, resid)
    return (
        positive_log_sum(schur, "observed-block Schur complement"),
        float(np.vdot(resid, resid / schur)),
    )


class KronCalibrationDensity:
    """Calibration log-density (eq. 12) with the hyperparameters fixed.

    Built once from the design, the periods' variable conditions, the fitted
    kernels and the weights; then :meth:`logpdf` costs ``O(R^2 + R m*)`` per
    basis on a full grid (method ``"schur"``). Immutable as far as a caller can
    tell: :meth:`with_observations` returns a new object, and the only internal
    state is memos of pieces a Gibbs sweep leaves unchanged (the simulator
    blocks depend on ``lambda`` alone, the rotated kernel vector on ``theta*``
    alone; see :meth:`_reset_memos`); they are not pickled.

    Parameters
    ----------
    theta
        Design, shape ``(R, t)``, scaled to [0, 1]. [-]
    x
        Variable conditions of the ``m*`` periods, shape ``(m*, s)``, scaled. [-]
    kernels
        Fitted hyperparameters, one :class:`SeparableKernel` per basis.
    ktk
        ``k_j^T k_j``, shape ``(p,)``. [-]
    w
        Simulator weights ``W_hat``, shape ``(R m*, p)``, run-major rows. [-]
    w_star
        Observed weights ``W*_hat``, shape ``(m_obs, p)``. [-]
    obs_index
        The periods the rows of ``w_star`` belong to; all ``m*`` when omitted.
    method
        ``"schur"`` (any observed subset, per-period nuggets) or ``"eigen"``
        (full grid and uniform ``a*`` only; the construction of method.md).
    """

    def __init__(
        self,
        theta: ArrayLike,
        x: ArrayLike,
        kernels: Sequence[SeparableKernel],
        ktk: ArrayLike,
        w: ArrayLike,
        w_star: ArrayLike,
        obs_index: ArrayLike | None = None,
        method: Method = "schur",
    ) -> None:
        if method not in ("schur", "eigen"):
            raise ValueError(f"method must be 'schur' or 'eigen', got {method!r}")
        self._data = GridData.build(theta, x, kernels, ktk, w, w_star, obs_index)
        self._method: Method = method
        self._full_grid = self._data.obs_index.size == self._data.x.shape[0]
        if method == "eigen" and not self._full_grid:
            raise ValueError("method 'eigen' needs every period observed; use 'schur'")
        self._grid = StackedGrid.of(self._data)
        self._reset_memos()

    def _reset_memos(self) -> None:
        """Memos of what a Gibbs sweep leaves unchanged, each keeping two entries.

        Simulator blocks depend on ``a`` (lambda) only, ``Q_t^T c`` on theta*
        only, ``u`` and ``g`` on both: a theta* move reuses the first, a
        lambda move the second, a lambda* move all three. Two entries, so that
        the current state survives one rejected proposal. Grouped noise (AR(1)
        errors) also keeps the list of simulator blocks per ``a`` and the fixed
        overlaps ``Q_x,j^T Q_x,k`` of each group's bases.
        """
        n = self._data.n_bases
        self._sim_memo: list[Lru] = [Lru() for _ in range(n)]
        self._c_hat_memo = Lru()
        self._u_g_memo = Lru()
        self._overlaps: dict[tuple[int, ...], FloatArray] = {}
        self._sims_memo = Lru()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        for key in _MEMOS:
            state.pop(key)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._reset_memos()

    @property
    def data(self) -> GridData:
        """The validated fixed inputs."""
        return self._data

    def stacked_grid(self) -> StackedGrid:
        """The fixed arrays of eq. 16 (:class:`~bayescal.calibration.grid.StackedGrid`)."""
        return self._grid

    def with_observations(self, w_star: ArrayLike) -> KronCalibrationDensity:
        """A new density with other observed weights (e.g. re-estimated by eq. 20).

        The eigen-decompositions are reused (:meth:`StackedGrid.with_observations`):
        a new ``w*`` costs ``O(p m*^2)``. So are the memos, shared with this
        density: none of their pieces depends on ``w*`` (the simulator blocks on
        ``lambda``, ``Q_t^T c`` on theta*, ``u`` and ``g`` on both, the overlaps
        on ``Q_x``), so a sampler that moves an AR(1) coefficient, which changes
        the observed weights alone, recomputes only the observed block.
        """
        new = object.__new__(type(self))  # a shallow copy that shares the memos
        new.__dict__.update(self.__dict__)
        new._grid = self._grid.with_observations(w_star)
        new._data = new._grid.data
        return new

    def pieces_grouped(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        groups: Sequence[tuple[Sequence[int], FloatArray]],
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity:
        """Log-density when some bases' observed weights share a noise block per period.

        Parameters
        ----------
        theta_star
            Calibration parameters ``(t,)``, scaled to [0, 1]. [-]
        a
            Simulator nuggets ``(p,)``. [-]
        a_star
            Observation nuggets ``(p,)`` of the bases in no group (others ignored). [-]
        groups
            ``(bases, noise)``: the bases of one output and the covariance
            ``(q, q)`` of their observed weights' noise in every period. [-]
        delta
            Model-discrepancy variance per basis ``(p,)`` (see :meth:`pieces_nuggets`). [-]
        constraint
            ``F`` of an orthogonal discrepancy (see :meth:`pieces_nuggets`). [-]
        """
        if self._method != "schur":
            raise ValueError("grouped observation noise needs method 'schur'")
        d = self._data
        ts = np.asarray(theta_star, dtype=float).reshape(1, -1)
        a_arr = np.broadcast_to(np.asarray(a, dtype=float), (d.n_bases,))
        as_arr = np.broadcast_to(np.asarray(a_star, dtype=float), (d.n_bases,))
        grouped = {j for bases, _ in groups for j in bases}
        dl = (
            np.zeros(d.n_bases)
            if delta is None
            else np.broadcast_to(np.asarray(delta, float), (d.n_bases,))
        )
        acc = None if constraint is None else Woodbury(self._grid, np.asarray(constraint), dl)
        if self._full_grid:  # through the memos, every block in the rotated bases
            grid = self._grid
            a_c = np.ascontiguousarray(a_arr)
            a_key, ts_key = a_c.tobytes(), ts.tobytes()
            sims = self._sims_memo.get(
                a_key, lambda: [self._sim(j, float(a_j)) for j, a_j in enumerate(a_c)]
            )
            c_hat = self._c_hat_memo.get(ts_key, lambda: _c_hat(grid, ts))
            u, g = self._u_g_memo.get(ts_key + a_key, lambda: _u_g(grid, c_hat, sims))
            parts = [
                (list(bases), np.asarray(noise, float), self._overlap(tuple(bases)))
                for bases, noise in groups
            ]
            out = _finish_grouped(grid, sims, u, g, np.asarray(as_arr), parts, np.asarray(dl), acc)
            return out if acc is None else out + acc.finish()
        diff = d.theta - ts
        bases = self._grid.bases
        cs = [b.kernel.variance * np.exp(-((diff * diff) @ b.beta_theta)) for b in bases]
        total = LogDensity.zero()
        for j, cache in enumerate(bases):
            if j not in grouped:
                nug = np.full(d.obs_index.size, float(as_arr[j]))
                sim = self._sim(j, float(a_arr[j]))
                total = total + _schur_basis(
                    cache, sim, cs[j], nug, False, float(dl[j]), None if acc is None else (acc, j)
                )
        for members, noise in groups:
            idx = list(members)
            sims = [self._sim(j, float(a_arr[j])) for j in idx]
            total = total + _grouped_bases(
                [bases[j] for j in idx],
                sims,
                [cs[j] for j in idx],
                np.asarray(noise, float),
                [float(dl[j]) for j in idx],
                None if acc is None else (acc, idx),
            )
        return total if acc is None else total + acc.finish()

    def pieces_nuggets(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity:
        """Log-density summed over bases for explicit nuggets.

        Parameters
        ----------
        theta_star
            Calibration parameters, shape ``(t,)``, scaled to [0, 1]. [-]
        a
            Simulator nuggets ``(lambda k_j^T k_j)^-1``, shape ``(p,)``. [-]
        a_star
            Observation nuggets, shape ``(p,)`` or ``(p, m_obs)`` (per-period
            ``B_j`` of the difference process). [-]
        delta
            Variance of a model discrepancy per basis ``(p,)``: the observed
            weights get ``delta_j c_x(x, x')`` more covariance (a GP over the
            periods' conditions, independent of the simulator); ``None``: none. [-]
        constraint
            ``F`` ``(p, m_obs, K)``: the discrepancy is conditioned on ``sum_j F_j^T
            delta_j = 0`` (the orthogonal discrepancy,
            :mod:`~bayescal.calibration.orthogonal`); needs ``delta``. [-]
        """
        d = self._data
        dl = None if delta is None else np.broadcast_to(np.asarray(delta, float), (d.n_bases,))
        acc = None
        if constraint is not None:
            if dl is None or self._method != "schur":
                raise ValueError("an orthogonal discrepancy needs delta and method 'schur'")
            acc = Woodbury(self._grid, np.asarray(constraint, float), np.asarray(dl))
        ts = np.asarray(theta_star, dtype=float).reshape(1, -1)
        a_arr = np.asarray(a, dtype=float)
        if a_arr.shape != (d.n_bases,):
            a_arr = np.broadcast_to(a_arr, (d.n_bases,))
        uniform = self._uniform_obs_nuggets(a_star)
        if self._full_grid and self._method == "schur" and uniform is not None:
            if not (a_arr.min() > 0.0 and uniform.min() > 0.0):
                raise ValueError("nuggets a and a* must be > 0")
            return self._stacked_pieces(ts, a_arr, uniform, dl, acc)
        as_arr = broadcast_obs_nuggets(a_star, d.n_bases, d.obs_index.size)
        if not (np.all(a_arr > 0.0) and np.all(as_arr > 0.0)):
            raise ValueError("nuggets a and a* must be > 0")
        total = LogDensity.zero()
        for j, cache in enumerate(self._grid.bases):
            diff = d.theta - ts
            c = cache.kernel.variance * np.exp(-((diff * diff) @ cache.beta_theta))
            if self._method == "eigen":
                if np.any(as_arr[j] != as_arr[j, 0]) or dl is not None:
                    raise ValueError("method 'eigen' needs a uniform a* and no delta; use 'schur'")
                part = _eigen_basis(cache, c, float(a_arr[j]), float(as_arr[j, 0]))
            else:
                sim = self._sim(j, float(a_arr[j]))
                extra = 0.0 if dl is None else float(dl[j])
                basis = None if acc is None else (acc, j)
                part = _schur_basis(cache, sim, c, as_arr[j], self._full_grid, extra, basis)
            total = total + part
        return total if acc is None else total + acc.finish()

    def _uniform_obs_nuggets(self, a_star: ArrayLike) -> FloatArray | None:
        """``a*`` as one value per basis ``(p,)`` if it is uniform over periods, else None."""
        arr = np.asarray(a_star, dtype=float)
        p = self._data.n_bases
        if arr.ndim == 1 and arr.size == p:
            return arr
        if arr.ndim == 0:
            return np.broadcast_to(arr, (p,))
        if arr.ndim == 2 and arr.shape[0] == p and arr.shape[1] >= 1:
            first = arr[:, 0]
            if np.all(arr == first[:, None]):
                return first
        return None

    def _stacked_pieces(
        self,
        ts: FloatArray,
        a: FloatArray,
        a_star: FloatArray,
        delta: FloatArray | None = None,
        acc: Woodbury | None = None,
    ) -> LogDensity:
        """The full-grid path with uniform ``a*``, through the memos."""
        grid = self._grid
        a_key, ts_key = a.tobytes(), ts.tobytes()
        sims = [self._sim(j, float(a_j)) for j, a_j in enumerate(a)]
        c_hat = self._c_hat_memo.get(ts_key, lambda: _c_hat(grid, ts))
        u, g = self._u_g_memo.get(ts_key + a_key, lambda: _u_g(grid, c_hat, sims))
        out = _finish(grid, sims, u, g, a_star, delta, acc)
        return out if acc is None else out + acc.finish()

    def mean_gradient(self, theta_star: ArrayLike, a: ArrayLike) -> FloatArray:
        """``d mean / d theta*`` of the emulator's weights at the observed periods.

        The mean of eq. 12's observed weights given the simulator weights (nuggets
        ``a``), differentiated analytically
        (:func:`~bayescal.calibration.orthogonal.rotated_gradient`),
        ``(p, m_obs, t)``. [-]
        """
        a_arr = np.broadcast_to(np.asarray(a, dtype=float), (self._data.n_bases,))
        hs = [self._sim(j, float(a_j)).h for j, a_j in enumerate(a_arr)]
        rot = rotated_gradient(self._grid, np.asarray(theta_star, float), hs)
        out: FloatArray = self._grid.p_obs @ rot
        return out

    def _overlap(self, bases: tuple[int, ...]) -> FloatArray:
        """``Q_x,j^T Q_x,k`` of a noise group's bases, ``(q, m*, q, m*)`` (fixed, kept)."""
        found: FloatArray | None = self._overlaps.get(bases)
        if found is None:
            q = np.stack([self._grid.bases[j].eig_x.vectors for j in bases])
            found = np.einsum("jia,kib->jakb", q, q)
            self._overlaps[bases] = found
        return found

    def _sim(self, j: int, a: float) -> _SimBlock:
        block: _SimBlock = self._sim_memo[j].get(
            np.float64(a).tobytes(), lambda: _sim_block(self._grid.bases[j], a)
        )
        return block

    def pieces(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> LogDensity:
        """Log-density and its pieces for precisions ``lambda`` and ``lambda*``.

        ``lam_star`` may be a scalar or one precision per observed period.
        """
        lam_s = np.asarray(lam_star, dtype=float)
        if lam_s.ndim == 0:  # the common case, without broadcasting to every period
            ktk = self._data.ktk
            return self.pieces_nuggets(theta_star, 1.0 / (float(lam) * ktk), 1.0 / (ktk * lam_s))
        a, a_star = self._data.nuggets(lam, lam_star)
        return self.pieces_nuggets(theta_star, a, a_star)

    def logpdf(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> float:
        """``sum_j log N(v_j; 0, Omega_j)`` (eq. 12 with its normalising constant)."""
        return self.pieces(theta_star, lam, lam_star).logpdf

    def logpdf_batch(
        self,
        theta_star: ArrayLike,
        lam: ArrayLike,
        lam_star: ArrayLike,
        *,
        errors: BatchErrors = "raise",
    ) -> FloatArray:
        """:meth:`logpdf` at ``B`` points in one call (:mod:`bayescal.calibration.batch`).

        Equal to a loop of :meth:`logpdf` up to rounding (the same BLAS calls
        per point; ~1e-15 relative); faster where the Python overhead of
        single calls dominates (small ``R x m*``, many points). On a full grid
        with method ``"schur"`` the points are evaluated together
        (:mod:`bayescal.calibration.batch`); otherwise this is that loop.
        Nothing is memoised between calls: a sampler that moves one group of
        coordinates at a time uses :meth:`batch_session`.

        Parameters
        ----------
        theta_star
            Calibration parameters ``(B, t)``, scaled to [0, 1]. [-]
        lam
            Simulator precisions ``(B,)``, > 0. [-]
        lam_star
            Observation precisions ``(B,)``, > 0. [-]
        errors
            ``"raise"``: a covariance that is not positive definite raises
            ``numpy.linalg.LinAlgError`` (as :meth:`logpdf`); ``"-inf"``: its
            point gets ``-inf``.

        Returns
        -------
        numpy.ndarray
            Log-densities ``(B,)``.
        """
        ts, lam_arr, lam_s = check_batch_args(self._data, theta_star, lam, lam_star, errors)
        if not self._batched:
            return logpdf_loop(self, ts, lam_arr, lam_s, errors)
        values, ok = batch_logpdf(self._grid, ts, lam_arr, lam_s)
        return checked(values, ok, errors, ts, lam_arr, lam_s)

    def batch_session(
        self, theta_star: ArrayLike, lam: ArrayLike, lam_star: ArrayLike
    ) -> BatchSession | None:
        """A :class:`~bayescal.calibration.batch.BatchSession` at ``B`` current points.

        For lockstep samplers: it evaluates proposals that move theta*,
        lambda or lambda* of every point and keeps what the move left
        unchanged. ``None`` where :meth:`logpdf_batch` would loop (not a full
        grid, or method ``"eigen"``). Arguments as :meth:`logpdf_batch`.
        """
        ts, lam_arr, lam_s = check_batch_args(self._data, theta_star, lam, lam_star)
        if not self._batched:
            return None
        return BatchSession(self._grid, ts, lam_arr, lam_s)

    @property
    def _batched(self) -> bool:
        """Whether :mod:`bayescal.calibration.batch` evaluates points together here."""
        return self._full_grid and self._method == "schur"


class CalibrationAlgebra(Protocol):
    """What the calibration posterior and its samplers need from a likelihood back end.

    Both back ends (:class:`KronCalibrationDensity`, and
    :class:`~bayescal.calibration.dense.DenseCalibrationDensity` for reference)
    implement all of it; ``batch_session`` returns ``None`` where a back end
    has no batched form (then lockstep chains evaluate point by point) and
    ``grid`` where it has no stacked grid (the JAX route needs one).
    """

    @property
    def data(self) -> GridData: ...

    def pieces_nuggets(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity: ...

    def mean_gradient(self, theta_star: ArrayLike, a: ArrayLike) -> FloatArray: ...

    def pieces(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> LogDensity: ...

    def pieces_grouped(
        self,
        theta_star: ArrayLike,
        a: ArrayLike,
        a_star: ArrayLike,
        groups: Sequence[tuple[Sequence[int], FloatArray]],
        delta: ArrayLike | None = None,
        constraint: ArrayLike | None = None,
    ) -> LogDensity: ...

    def logpdf(self, theta_star: ArrayLike, lam: float, lam_star: ArrayLike) -> float: ...

    def logpdf_batch(
        self,
        theta_star: ArrayLike,
        lam: ArrayLike,
        lam_star: ArrayLike,
        *,
        errors: BatchErrors = "raise",
    ) -> FloatArray: ...

    def batch_session(
        self, theta_star: ArrayLike, lam: ArrayLike, lam_star: ArrayLike
    ) -> BatchSession | None: ...

    def stacked_grid(self) -> StackedGrid | None: ...

    def with_observations(self, w_star: ArrayLike) -> CalibrationAlgebra: ...


Kind = Literal["kronecker", "dense"]


def make_algebra(
    kind: Kind,
    theta: ArrayLike,
    x: ArrayLike,
    kernels: Sequence[SeparableKernel],
    ktk: ArrayLike,
    w: ArrayLike,
    w_star: ArrayLike,
    obs_index: ArrayLike | None = None,
) -> CalibrationAlgebra:
    """Calibration log-density back end: ``"kronecker"`` (fast) or ``"dense"`` (reference).

    Arguments after ``kind`` as :class:`KronCalibrationDensity`.
    """
    if kind == "kronecker":
        return KronCalibrationDensity(theta, x, kernels, ktk, w, w_star, obs_index)
    if kind == "dense":
        return DenseCalibrationDensity(theta, x, kernels, ktk, w, w_star, obs_index)
    raise ValueError(f"algebra must be 'kronecker' or 'dense', got {kind!r}")
