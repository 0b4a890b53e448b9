"""What eq. 16 needs that never moves during a calibration, built in one place.

With the emulator's hyperparameters fixed, everything in the calibration
likelihood that does not depend on ``theta*``, ``lambda`` or ``lambda*`` is
computed once here (method.md section 5; the algebra is in the docstring of
:mod:`bayescal.calibration.kron`): per basis ``j`` the eigen-decompositions
``S_theta = Q_t L_t Q_t^T`` and ``S_x = Q_x L_x Q_x^T``, the rotated
simulator weights ``Wt = Q_t^T W Q_x`` and the rotated observations
``Q_x^T w*`` (the observed periods placed by ``obs_index``, zeros elsewhere).

:class:`StackedGrid` holds them per basis (:class:`BasisPieces`, for the
general Schur route with missing periods or per-period nuggets) and stacked
over the bases (for the full-grid route). The same object serves the three
evaluations of eq. 16: one point at a time
(:class:`~bayescal.calibration.kron.KronCalibrationDensity`), ``B`` points at
once for chains in lockstep (:mod:`bayescal.calibration.batch`) and the JAX
log posterior of NUTS (:mod:`bayescal.calibration.hmc`).

The stacked arrays are copies of the per-basis ones, value for value, so the
three agree to rounding; where a route multiplies by ``Q_t^T`` it uses the
contiguous ``q_t_trans`` (full grid) or the transposed eigenvectors (general
route) exactly as before this module existed, so results are unchanged bit
for bit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.emulator.dense import GridData
from bayescal.emulator.kernel import FloatArray, SeparableKernel
from bayescal.emulator.kron import SymEig

__all__ = ["BasisPieces", "StackedGrid"]


@dataclass(frozen=True)
class BasisPieces:
    """What never moves during calibration, for one basis.

    Attributes
    ----------
    kernel
        The basis's hyperparameters (MAP).
    beta_theta
        ``-4 ln rho`` of the theta inputs ``(t,)``. [-]
    s_theta
        ``S_theta`` ``(R, R)`` (with ``tau^-1``).
    eig_theta, eig_x
        Eigen-decompositions of ``S_theta`` and ``S_x``.
    w_rot
        ``Q_t^T W Q_x`` ``(R, m*)``. [-]
    w_x
        ``W Q_x`` ``(R, m*)`` (the ``"eigen"`` route). [-]
    obs_rot
        ``Q_x^T w*`` with the observed periods placed by ``obs_index``, zeros
        elsewhere ``(m*,)`` (meaningful on a full grid). [-]
    obs
        ``w*`` of this basis ``(m_obs,)``. [-]
    p_obs
        ``Q_x[O, :]``, the observed rows of ``Q_x`` ``(m_obs, m*)``.
    sx_obs
        ``S_x[O, O]`` ``(m_obs, m_obs)``.
    """

    kernel: SeparableKernel
    beta_theta: FloatArray
    s_theta: FloatArray
    eig_theta: SymEig
    eig_x: SymEig
    w_rot: FloatArray
    w_x: FloatArray
    obs_rot: FloatArray
    obs: FloatArray
    p_obs: FloatArray
    sx_obs: FloatArray

    def with_observations(self, d: GridData, j: int) -> BasisPieces:
        """The same basis with the observed weights of ``d`` (eigen-decompositions kept)."""
        obs = np.zeros(0) if d.w_star is None else d.w_star[:, j]
        obs_full = np.zeros(d.x.shape[0])
        if obs.size == d.x.shape[0]:
            obs_full[d.obs_index] = obs
        # a shallow copy with two fields set: dataclasses.replace re-runs __init__ and
        # copy.copy goes through __reduce_ex__, each costing as much as the rest when an
        # AR(1) coefficient's move asks for new observed weights
        new = object.__new__(BasisPieces)
        new.__dict__.update(self.__dict__, obs=obs, obs_rot=self.eig_x.vectors.T @ obs_full)
        return new

    @classmethod
    def build(cls, d: GridData, j: int) -> BasisPieces:
        """Basis ``j`` of the validated inputs ``d``."""
        kern = d.kernels[j]
        n_runs, n_per = d.theta.shape[0], d.x.shape[0]
        s_theta = kern.theta_cov(d.theta)
        s_x = kern.x_corr(d.x)
        eig_t, eig_x = SymEig.of(s_theta), SymEig.of(s_x)
        w = d.w[:, j].reshape(n_runs, n_per)
        w_x = w @ eig_x.vectors
        obs = np.zeros(0) if d.w_star is None else d.w_star[:, j]
        obs_full = np.zeros(n_per)
        if obs.size == n_per:
            obs_full[d.obs_index] = obs
        idx = d.obs_index
        return cls(
            kernel=kern,
            beta_theta=kern.beta_theta,
            s_theta=s_theta,
            eig_theta=eig_t,
            eig_x=eig_x,
            w_rot=eig_t.vectors.T @ w_x,
            w_x=w_x,
            obs_rot=eig_x.vectors.T @ obs_full,
            obs=obs,
            p_obs=eig_x.vectors[idx, :],
            sx_obs=s_x[np.ix_(idx, idx)],
        )


@dataclass(frozen=True)
class StackedGrid:
    """The fixed arrays of eq. 16, per basis and stacked over the ``p`` bases.

    Build with :meth:`of`. Shapes: ``R`` runs, ``t`` parameters, ``m*``
    periods, ``p`` bases.

    Attributes
    ----------
    data
        The validated inputs (design, conditions, kernels, weights, ``obs_index``).
    bases
        :class:`BasisPieces` of every basis.
    theta
        Design ``(R, t)``, scaled to [0, 1]. [-]
    beta_theta
        ``-4 ln rho`` of the theta inputs ``(t, p)``. [-]
    variance
        ``1 / tau`` per basis ``(p,)``. [-]
    q_t_trans
        ``Q_t^T`` per basis ``(p, R, R)``, C-contiguous.
    l_t, l_x
        Eigenvalues of ``S_theta`` ``(p, R)`` and ``S_x`` ``(p, m*)``.
    w_rot
        ``Q_t^T W Q_x`` ``(p, R, m*)``. [-]
    obs_rot
        ``Q_x^T w*`` ``(p, m*)`` (observed periods placed by ``obs_index``). [-]
    ktk
        ``k_j^T k_j`` ``(p,)``. [-]
    """

    data: GridData
    bases: tuple[BasisPieces, ...]
    theta: FloatArray
    beta_theta: FloatArray
    variance: FloatArray
    q_t_trans: FloatArray
    l_t: FloatArray
    l_x: FloatArray
    w_rot: FloatArray
    obs_rot: FloatArray
    ktk: FloatArray

    @classmethod
    def of(cls, data: GridData) -> StackedGrid:
        """Everything fixed, from the validated inputs (one eigen-decomposition pair per basis)."""
        bases = tuple(BasisPieces.build(data, j) for j in range(data.n_bases))
        return cls(
            data=data,
            bases=bases,
            theta=data.theta,
            beta_theta=np.stack([b.beta_theta for b in bases], axis=1),
            variance=np.array([float(b.kernel.variance) for b in bases]),
            q_t_trans=np.ascontiguousarray(np.stack([b.eig_theta.vectors.T for b in bases])),
            l_t=np.stack([b.eig_theta.values for b in bases]),
            l_x=np.stack([b.eig_x.values for b in bases]),
            w_rot=np.stack([b.w_rot for b in bases]),
            obs_rot=np.stack([b.obs_rot for b in bases]),
            ktk=data.ktk,
        )

    def with_observations(self, w_star: ArrayLike) -> StackedGrid:
        """The same grid with other observed weights ``(m_obs, p)``: no new eigen-decomposition."""
        data = self.data.with_observations(w_star)
        bases = tuple(b.with_observations(data, j) for j, b in enumerate(self.bases))
        return dataclasses.replace(
            self, data=data, bases=bases, obs_rot=np.stack([b.obs_rot for b in bases])
        )

    @property
    def full_grid(self) -> bool:
        """Whether every period is observed (the fast, diagonal Schur route)."""
        return self.data.obs_index.size == self.data.x.shape[0]

    @property
    def n_bases(self) -> int:
        """``p``."""
        return len(self.bases)

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

    @cached_property
    def var_lx(self) -> FloatArray:
        """``l_x / tau`` per basis ``(p, m*)``."""
        return self.variance[:, None] * self.l_x

    @cached_property
    def p_obs(self) -> FloatArray:
        """``Q_x[O, :]`` per basis ``(p, m_obs, m*)``."""
        return np.stack([b.p_obs for b in self.bases])

    @cached_property
    def sx_obs(self) -> FloatArray:
        """``S_x[O, O]`` per basis ``(p, m_obs, m_obs)``."""
        return np.stack([b.sx_obs for b in self.bases])

    @cached_property
    def l_x2(self) -> FloatArray:
        """``l_x^2`` per basis ``(p, m*)``."""
        return self.l_x * self.l_x

    def kernel_vector(self, theta_star: FloatArray) -> FloatArray:
        """``c = S_theta(theta, theta*)`` per run and basis ``(R, p)`` for ``theta*`` ``(1, t)``."""
        diff = self.theta - theta_star
        out: NDArray[np.float64] = np.exp(-((diff * diff) @ self.beta_theta)) * self.variance
        return out
