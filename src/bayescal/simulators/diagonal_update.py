"""Repeated solves of one linear system whose diagonal changes on a few entries.

The built-in box's backward-Euler matrix changes from step to step only on the
diagonal entries of its outside-surface nodes (their long-wave and convective
coefficients) and, in free-float, of its air node (the window's conductance).
Factorising it once and correcting each step by the Woodbury identity costs one
pair of triangular solves and a small ``k x k`` solve per step instead of a new
factorisation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack, lu_factor

__all__ = ["DiagonalUpdateSolver"]


@dataclass(frozen=True)
class DiagonalUpdateSolver:
    """Solve ``(A0 + sum_i delta_i e_i e_i^T) x = b`` for diagonal changes on a few nodes.

    ``A0`` is factorised once; with ``Z = A0^-1 U`` (``U`` the columns ``e_i``),
    ``x = x0 - Z (I + D U^T Z)^-1 D U^T x0`` where ``x0 = A0^-1 b``.

    Attributes
    ----------
    lu, piv
        LU factorisation of ``A0`` (:func:`scipy.linalg.lu_factor`).
    z
        ``A0^-1 U``, shape ``(n, k)``.
    zu
        ``U^T Z``, the rows ``index`` of ``z``, shape ``(k, k)``.
    index
        The ``k`` diagonal entries that change.
    base
        Their values in ``A0``, shape ``(k,)``.
    """

    lu: np.ndarray
    piv: np.ndarray
    z: np.ndarray
    zu: np.ndarray
    index: np.ndarray
    base: np.ndarray

    @classmethod
    def build(cls, a0: np.ndarray, index: np.ndarray, base: np.ndarray) -> DiagonalUpdateSolver:
        """Factorise ``a0`` whose entries ``index`` on the diagonal hold ``base``."""
        lu, piv = lu_factor(a0, check_finite=False)
        cols = np.zeros((a0.shape[0], index.size))
        cols[index, np.arange(index.size)] = 1.0
        z = lapack.dgetrs(lu, piv, cols)[0]
        return cls(lu, piv, z, z[index, :], index, base)

    def solve(self, rhs: np.ndarray, diagonal: np.ndarray) -> np.ndarray:
        """Solution with the updated entries' values ``diagonal`` (base values + delta)."""
        x0 = lapack.dgetrs(self.lu, self.piv, rhs)[0]
        delta = diagonal - self.base
        y = lapack.dgesv(np.eye(delta.size) + delta[:, None] * self.zu, delta * x0[self.index])[2]
        return x0 - self.z @ y
