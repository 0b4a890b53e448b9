"""Finite-volume discretisation of 1-D conduction through a layered construction.

Vertex-centred scheme: nodes sit on both surfaces and on every layer
interface, with equal cells inside each layer. Each node carries the heat
capacity of the half cells beside it; neighbouring nodes are joined by the
conductance ``k / dx`` of the cell between them. Interfaces are nodes, so
interface temperatures and fluxes are read directly, and the scheme is second
order in space for piecewise-constant properties.

The semi-discrete system for node temperatures ``T`` is
``C dT/dt = -G T + b(t)``, with ``C`` diagonal (capacities) and ``G``
tridiagonal (conductances); boundary conditions add to ``G`` and ``b``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from bayescal.errors import SimulatorError


@dataclass(frozen=True)
class Layer:
    """A homogeneous layer.

    Parameters
    ----------
    name
        Identifier used to address the layer's properties (``"concrete"``).
    thickness
        Layer thickness. [m]
    conductivity
        Thermal conductivity. [W/(m·K)]
    density
        Density. [kg/m³]
    specific_heat
        Specific heat capacity. [J/(kg·K)]
    """

    name: str
    thickness: float
    conductivity: float
    density: float
    specific_heat: float

    def __post_init__(self) -> None:
        for prop in ("thickness", "conductivity", "density", "specific_heat"):
            value = getattr(self, prop)
            if not (np.isfinite(value) and value > 0):
                raise SimulatorError(f"layer {self.name!r}: {prop} must be > 0, got {value!r}")

    @property
    def diffusivity(self) -> float:
        """Thermal diffusivity ``k / (rho c)``. [m²/s]"""
        return self.conductivity / (self.density * self.specific_heat)

    @property
    def resistance(self) -> float:
        """Thermal resistance ``d / k``. [m²·K/W]"""
        return self.thickness / self.conductivity


LAYER_PROPERTIES = ("thickness", "conductivity", "density", "specific_heat")


def penetration_depth(layer: Layer, period: float) -> float:
    """Periodic penetration depth ``sqrt(a P / pi)`` (EN ISO 13786). [m]

    Parameters
    ----------
    layer
        The layer.
    period
        Period of the temperature variation. [s]
    """
    return math.sqrt(layer.diffusivity * period / math.pi)


@dataclass(frozen=True)
class Mesh:
    """Nodes and cells of a discretised construction (outside face first).

    Attributes
    ----------
    dx
        Cell widths, shape ``(n_cells,)``. [m]
    conductance
        Conductance ``k/dx`` of each cell, shape ``(n_cells,)``. [W/(m²·K)]
    capacity
        Heat capacity of each node, shape ``(n_cells + 1,)``. [J/(m²·K)]
    interface_nodes
        Node index of the outside face, every layer interface and the inside
        face, shape ``(n_layers + 1,)``.
    """

    dx: np.ndarray
    conductance: np.ndarray
    capacity: np.ndarray
    interface_nodes: tuple[int, ...]

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return int(self.capacity.size)

    def conduction_matrix(self) -> sparse.csr_matrix:
        """Tridiagonal conductance matrix ``G`` with no boundary terms. [W/(m²·K)]"""
        g = self.conductance
        main = np.zeros(self.n_nodes)
        main[:-1] += g
        main[1:] += g
        return sparse.diags([-g, main, -g], [-1, 0, 1], format="csr")


def cells_for_layer(layer: Layer, max_dx: float | None, min_cells: int) -> int:
    """Number of equal cells in ``layer`` so that no cell exceeds ``max_dx``."""
    if max_dx is None:
        return min_cells
    return max(min_cells, math.ceil(layer.thickness / max_dx - 1e-12))


def build_mesh(
    layers: Sequence[Layer],
    *,
    cells: Sequence[int] | None = None,
    period: float = 86400.0,
    cells_per_depth: float = 6.0,
    min_cells: int = 2,
) -> Mesh:
    """Discretise a construction.

    Parameters
    ----------
    layers
        Layers from the outside face to the inside face.
    cells
        Explicit number of cells per layer; overrides the automatic choice.
    period
        Shortest period of interest; cell sizes are chosen relative to each
        layer's penetration depth at this period. [s]
    cells_per_depth
        Cells per penetration depth (automatic choice). Larger is finer.
    min_cells
        Minimum number of cells in any layer.

    Returns
    -------
    Mesh
    """
    if len(layers) == 0:
        raise SimulatorError("a construction needs at least one layer")
    if cells is None:
        counts = [
            cells_for_layer(layer, penetration_depth(layer, period) / cells_per_depth, min_cells)
            for layer in layers
        ]
    else:
        counts = [int(c) for c in cells]
        if len(counts) != len(layers) or min(counts) < 1:
            raise SimulatorError(
                f"cells must give a positive count for each of the {len(layers)} layers, "
                f"got {list(cells)}"
            )
    dx = np.concatenate(
        [np.full(c, layer.thickness / c) for layer, c in zip(layers, counts, strict=True)]
    )
    k = np.concatenate(
        [np.full(c, layer.conductivity) for layer, c in zip(layers, counts, strict=True)]
    )
    rc = np.concatenate(
        [
            np.full(c, layer.density * layer.specific_heat)
            for layer, c in zip(layers, counts, strict=True)
        ]
    )
    half = 0.5 * rc * dx
    capacity = np.zeros(dx.size + 1)
    capacity[:-1] += half
    capacity[1:] += half
    interface_nodes = tuple(int(i) for i in np.concatenate([[0], np.cumsum(counts)]))
    return Mesh(dx=dx, conductance=k / dx, capacity=capacity, interface_nodes=interface_nodes)
