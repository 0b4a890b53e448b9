"""The box's repeated solver against a dense solve of the updated matrix."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.simulators.diagonal_update import DiagonalUpdateSolver


@pytest.mark.parametrize("k", [1, 3, 7])
def test_diagonal_update_equals_a_dense_solve(k: int) -> None:
    rng = np.random.default_rng(k)
    n = 40
    g = rng.normal(size=(n, n))
    a0 = g @ g.T + n * np.eye(n)  # well conditioned, like C/dt + G
    index = rng.choice(n, size=k, replace=False)
    solver = DiagonalUpdateSolver.build(a0, index, a0[index, index].copy())
    for _ in range(5):
        diagonal = a0[index, index] + rng.uniform(-5.0, 50.0, size=k)
        rhs = rng.normal(size=n)
        a = a0.copy()
        a[index, index] = diagonal
        np.testing.assert_allclose(solver.solve(rhs, diagonal), np.linalg.solve(a, rhs), atol=1e-10)
    # With no change it is the plain solve of A0.
    rhs = rng.normal(size=n)
    np.testing.assert_allclose(solver.solve(rhs, solver.base), np.linalg.solve(a0, rhs), atol=1e-12)
