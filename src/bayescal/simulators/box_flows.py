"""What drives the built-in test box at each instant, and the flows of a detailed run.

The records of :mod:`bayescal.simulators.box` (re-exported there): the
boundary conditions on the stepping grid, and a run's temperatures and energy
flows, which close its energy balance step by step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BoxRun", "Drivers"]


@dataclass(frozen=True)
class Drivers:
    """Boundary conditions on the stepping grid, shape ``(n,)`` or ``(n, 6)``.

    Attributes
    ----------
    temp_out
        Outside air (and ground) temperature. [°C]
    temp_sky
        Effective sky temperature. [°C]
    h_conv
        Exterior convective coefficient. [W/(m²·K)]
    solar_out
        Solar power absorbed at each face's outside surface. [W]
    solar_in
        Transmitted solar power absorbed at each face's inside surface. [W]
    solar_returned
        Transmitted solar power that leaves the inside surfaces again through
        the glazing (sent back out or absorbed in it). [W]
    window_absorbed
        Solar power absorbed in the glazing per glazed area (0 at the initial
        instant, a steady state without sun). [W/m²]
    control
        Imposed air temperature [°C] (coheating) or heat input [W] (free-float).
    """

    temp_out: np.ndarray
    temp_sky: np.ndarray
    h_conv: np.ndarray
    solar_out: np.ndarray
    solar_in: np.ndarray
    solar_returned: np.ndarray
    window_absorbed: np.ndarray
    control: np.ndarray


@dataclass(frozen=True)
class BoxRun:
    """A detailed run on the stepping grid (``n`` instants, ``dt`` apart).

    Energy flows are positive into the box; step ``j >= 1`` is the backward-Euler
    step from instant ``j-1`` to ``j`` and its flows are those of instant ``j``,
    so that ``stored[j] - stored[j-1] = dt * (heat_to_air + exterior.sum(1) +
    window + leak + solar_transmitted - solar_returned)[j]``. Entries at ``j = 0``
    belong to the initial steady state.

    Attributes
    ----------
    dt
        Step. [s]
    temperatures
        Node temperatures, shape ``(n, n_nodes)``: face ``f``'s mesh nodes
        (outside first) at ``f*m ... f*m + m - 1``, the air node last. [°C]
    capacity
        Node heat capacities, shape ``(n_nodes,)``. [J/K]
    heat_to_air
        Heat added to the air node (heating power or heat input). [W]
    exterior
        Heat entering each face at its outside surface (absorbed solar,
        convection, long-wave), shape ``(n, 6)``. [W]
    window
        Heat entering the air node through the glazing: conduction and the
        inward share of the solar power absorbed in the panes (transmitted
        solar excluded). [W]
    leak
        Heat entering the air node through ``ua_leak``. [W]
    solar_transmitted
        Solar power transmitted by the window. [W]
    solar_returned
        Part of it that reaches the glazing again from inside after
        reflections: sent back out or absorbed in the glazing (whose inward
        share is in ``window``). [W]
    solar_glazing
        Solar power absorbed in the glazing, from outside and from inside. [W]
    """

    dt: float
    temperatures: np.ndarray
    capacity: np.ndarray
    heat_to_air: np.ndarray
    exterior: np.ndarray
    window: np.ndarray
    leak: np.ndarray
    solar_transmitted: np.ndarray
    solar_returned: np.ndarray
    solar_glazing: np.ndarray

    @property
    def temp_air_in(self) -> np.ndarray:
        """Inside air temperature. [°C]"""
        return self.temperatures[:, -1]

    @property
    def stored(self) -> np.ndarray:
        """Stored heat relative to 0 °C. [J]"""
        return self.temperatures @ self.capacity
