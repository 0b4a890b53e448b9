"""Finite-volume discretisation of layered constructions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayescal.errors import SimulatorError
from bayescal.simulators.fvm import LAYER_PROPERTIES, Layer, build_mesh, penetration_depth

LAYERS = [
    Layer("fb_out", 0.027, 0.0316, 116.6, 840.0),
    Layer("concrete", 0.15, 0.12, 552.0, 800.0),
    Layer("fb_in", 0.027, 0.0316, 116.6, 840.0),
]


@pytest.mark.parametrize("prop", LAYER_PROPERTIES)
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
def test_layer_rejects_non_positive_or_non_finite_properties(prop, value):
    values = {"thickness": 0.1, "conductivity": 1.0, "density": 1000.0, "specific_heat": 900.0}
    values[prop] = value
    with pytest.raises(SimulatorError, match=f"{prop} must be > 0"):
        Layer("bad", **values)


def test_layer_derived_properties():
    layer = LAYERS[1]
    assert layer.resistance == pytest.approx(0.15 / 0.12, rel=1e-15)  # plain arithmetic
    assert layer.diffusivity == pytest.approx(0.12 / (552.0 * 800.0), rel=1e-15)


def test_penetration_depth_solves_the_periodic_heat_equation():
    layer, period = LAYERS[1], 86400.0
    delta = penetration_depth(layer, period)
    omega = 2 * np.pi / period
    a = layer.diffusivity

    def theta(x: float, t: float) -> float:  # damped wave of depth delta
        return math.exp(-x / delta) * math.cos(omega * t - x / delta)

    x, t, h, k = 0.05, 3000.0, 1e-4, 1.0
    dtheta_dt = (theta(x, t + k) - theta(x, t - k)) / (2 * k)
    d2theta_dx2 = (theta(x + h, t) - 2 * theta(x, t) + theta(x - h, t)) / h**2
    # Central differences: truncation ~ (h/delta)^2 ~ 1e-6 relative.
    assert dtheta_dt == pytest.approx(a * d2theta_dx2, rel=1e-5)


def test_mesh_conserves_capacity_and_resistance():
    mesh = build_mesh(LAYERS, period=3600.0)
    total_capacity = sum(layer.density * layer.specific_heat * layer.thickness for layer in LAYERS)
    # Sums of a few hundred terms: round-off only.
    assert mesh.capacity.sum() == pytest.approx(total_capacity, rel=1e-12)
    assert np.sum(1 / mesh.conductance) == pytest.approx(
        sum(layer.resistance for layer in LAYERS), rel=1e-12
    )
    positions = np.concatenate([[0.0], np.cumsum(mesh.dx)])
    np.testing.assert_allclose(
        positions[list(mesh.interface_nodes)],
        np.concatenate([[0.0], np.cumsum([layer.thickness for layer in LAYERS])]),
        rtol=1e-12,
    )
    assert mesh.n_nodes == mesh.dx.size + 1 == mesh.capacity.size


@pytest.mark.parametrize("cells_per_depth", [2.0, 6.0, 15.0])
def test_cells_are_the_fewest_within_the_depth_rule(cells_per_depth):
    period = 3600.0
    mesh = build_mesh(LAYERS, period=period, cells_per_depth=cells_per_depth, min_cells=2)
    counts = np.diff(mesh.interface_nodes)
    for layer, count in zip(LAYERS, counts, strict=True):
        limit = penetration_depth(layer, period) / cells_per_depth
        assert count >= 2
        assert layer.thickness / count <= limit * (1 + 1e-12)
        if count > 2:  # one cell fewer would break the rule
            assert layer.thickness / (count - 1) > limit


def test_explicit_cells_and_their_validation():
    mesh = build_mesh(LAYERS, cells=[1, 5, 3])
    assert mesh.interface_nodes == (0, 1, 6, 9)
    with pytest.raises(SimulatorError, match="positive count for each of the 3 layers"):
        build_mesh(LAYERS, cells=[1, 5])
    with pytest.raises(SimulatorError, match="positive count"):
        build_mesh(LAYERS, cells=[1, 0, 3])
    with pytest.raises(SimulatorError, match="at least one layer"):
        build_mesh([])


def test_conduction_matrix_is_symmetric_and_exact_in_steady_state():
    mesh = build_mesh(LAYERS, cells=[3, 7, 3])
    g = mesh.conduction_matrix().toarray()
    np.testing.assert_array_equal(g, g.T)
    # Row sums vanish: a uniform temperature conducts nothing (round-off only).
    np.testing.assert_allclose(g.sum(axis=1), 0.0, atol=1e-12 * np.abs(g).max())
    # The piecewise-linear steady profile balances at every interior node.
    resist = np.concatenate([[0.0], np.cumsum(1 / mesh.conductance)])
    temps = 20.0 - 25.0 * resist / resist[-1]
    np.testing.assert_allclose((g @ temps)[1:-1], 0.0, atol=1e-10)
