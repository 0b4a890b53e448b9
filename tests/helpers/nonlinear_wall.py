"""A wall whose conductivities rise with temperature: a model error the 3-layer model lacks.

Every layer's conductivity follows ``k(T) = k_10 (1 + beta (T - 10 °C))``, ``k_10`` being
the value the calibrated model uses (the declared value at 10 °C mean temperature, as in
EN ISO 10456) and ``beta`` a temperature coefficient of the size EN ISO 10456 tabulates
for the materials: about 0.5 % per kelvin for mineral and glass fibre, a few tenths of a
percent for dry aerated concrete. The calibrated wall keeps each conductivity constant.

The truth is integrated on the calibrated model's own mesh
(:meth:`MultilayerWall.propagator`'s ``mesh``), each cell's conductance taken at the mean
of its two nodes' temperatures: for a conductivity linear in temperature this is the
Kirchhoff transform of the cell, so the steady state is exact on any mesh (tested against
the closed form). The interior nodes' ODE ``C dT/dt = -G(T) T + b(t)`` (surface
temperatures imposed, linear between clock samples) is solved by SciPy's BDF; the inside
flux is read as :mod:`bayescal.simulators.wall` reads it (conduction through the last
cell less the storage of its half cell, the surface's rate the mean of the two clock
intervals' slopes). With ``beta = 0`` it reproduces the ``"exact"`` scheme of the
calibrated wall (tested).

What "the truth" of the derived quantities is for such a wall: the steady resistance at
the experiment's mean surface temperatures (what a guarded hot box at those conditions
would measure), from the steady state of the same discretisation.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy import sparse
from scipy.integrate import solve_ivp

from bayescal.simulators.base import Forcing
from bayescal.simulators.fvm import Mesh
from bayescal.simulators.wall import MultilayerWall
from virtual_wall import STEP, paper_wall

REFERENCE = 10.0  # [°C] the temperature of the declared conductivities
#: Temperature coefficients [1/K]: glass-fibre boards and aerated concrete.
REALISTIC = {"fb_out": 0.005, "concrete": 0.002, "fb_in": 0.005}


class ConductivityWall:
    """The paper's wall (:func:`paper_wall`) with temperature-dependent conductivities.

    Parameters
    ----------
    beta
        Layer name -> temperature coefficient of its conductivity. [1/K]
    wall
        The constant-conductivity wall it departs from (default :func:`paper_wall`).
    """

    def __init__(self, beta: Mapping[str, float], wall: MultilayerWall | None = None) -> None:
        self.wall = paper_wall() if wall is None else wall
        names = [layer.name for layer in self.wall.layers]
        unknown = set(beta) - set(names)
        if unknown:
            raise ValueError(f"no layer named {sorted(unknown)}; the wall has {names}")
        self.beta = {name: float(beta.get(name, 0.0)) for name in names}

    # -- the discretisation --------------------------------------------------------------
    def _cells(
        self, parameters: Mapping[str, float], step: float
    ) -> tuple[Mesh, np.ndarray, np.ndarray, np.ndarray]:
        """The calibrated wall's mesh, each cell's ``k_10``, ``beta`` and half-cell capacity."""
        mesh = self.wall.propagator(parameters, step).mesh
        layers = self.wall.wall_state(parameters).layers
        counts = np.diff(mesh.interface_nodes)
        k10 = np.repeat([la.conductivity for la in layers], counts)
        beta = np.repeat([self.beta[la.name] for la in layers], counts)
        half = 0.5 * np.repeat([la.density * la.specific_heat for la in layers], counts) * mesh.dx
        return mesh, k10, beta, half

    @staticmethod
    def _conductance(
        temps: np.ndarray, mesh: Mesh, k10: np.ndarray, beta: np.ndarray
    ) -> np.ndarray:
        """Each cell's conductance at the mean of its nodes' temperatures. [W/(m²·K)]"""
        mean = 0.5 * (temps[..., :-1] + temps[..., 1:])
        return k10 * (1.0 + beta * (mean - REFERENCE)) / mesh.dx

    def steady(self, parameters: Mapping[str, float], t_out: float, t_in: float) -> np.ndarray:
        """Node temperatures in steady state between surface temperatures ``t_out``,
        ``t_in``: equal flux through every cell, each cell's Kirchhoff transform. [°C]"""
        mesh, k10, beta, _ = self._cells(parameters, STEP)
        temps = np.linspace(t_out, t_in, mesh.n_nodes)
        for _ in range(100):
            g = self._conductance(temps, mesh, k10, beta)
            flux = (t_out - t_in) / np.sum(1.0 / g)
            new = t_out - np.concatenate([[0.0], np.cumsum(flux / g)])
            if np.max(np.abs(new - temps)) < 1e-13:
                return new
            temps = new
        raise RuntimeError("the steady state did not converge")

    # -- the simulator interface of the experiments -------------------------------------
    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        """Inside heat flux (positive wall -> room) under imposed surface temperatures,
        starting in steady state at the first sample. [W/m²]"""
        step = forcing.step
        t_out = np.asarray(forcing["temp_surf_out"], float)
        t_in = np.asarray(forcing["temp_surf_in"], float)
        n = t_out.size
        mesh, k10, beta, half = self._cells(parameters, step)
        cap = mesh.capacity[1:-1]
        clock = np.arange(n) * step

        def surfaces(t: float) -> tuple[float, float]:
            return float(np.interp(t, clock, t_out)), float(np.interp(t, clock, t_in))

        def rhs(t: float, inner: np.ndarray) -> np.ndarray:
            a, b = surfaces(t)
            temps = np.concatenate([[a], inner, [b]])
            q = self._conductance(temps, mesh, k10, beta) * (temps[:-1] - temps[1:])
            return (q[:-1] - q[1:]) / cap

        m = cap.size
        pattern = sparse.diags([np.ones(m - 1), np.ones(m), np.ones(m - 1)], [-1, 0, 1])
        start = self.steady(parameters, t_out[0], t_in[0])[1:-1]
        sol = solve_ivp(
            rhs,
            (0.0, clock[-1]),
            start,
            method="BDF",
            t_eval=clock,
            max_step=step,
            rtol=1e-9,
            atol=1e-9,
            jac_sparsity=pattern,
        )
        if not sol.success:
            raise RuntimeError(f"the nonlinear wall's integration failed: {sol.message}")
        temps = np.column_stack([t_out, sol.y.T, t_in])
        mean_last = 0.5 * (temps[:, -2] + temps[:, -1])
        g_last = k10[-1] * (1.0 + beta[-1] * (mean_last - REFERENCE)) / mesh.dx[-1]
        slopes = np.diff(t_in) / step
        rate = np.empty(n)
        rate[0], rate[-1] = slopes[0], slopes[-1]
        rate[1:-1] = 0.5 * (slopes[:-1] + slopes[1:])
        flux = g_last * (temps[:, -2] - temps[:, -1]) - half[-1] * rate
        return {"heat_flux_in": flux}

    def derived_at(
        self, parameters: Mapping[str, float], t_out: float, t_in: float
    ) -> dict[str, float]:
        """R, U and areal heat capacity of the wall, R (and so U) the steady resistance at
        mean surface temperatures ``t_out``, ``t_in``; ``parameters`` are the values at
        10 °C."""
        mesh, k10, beta, _ = self._cells(parameters, STEP)
        temps = self.steady(parameters, t_out, t_in)
        r_wall = float(np.sum(1.0 / self._conductance(temps, mesh, k10, beta)))
        at_reference = self.wall.derived(parameters)
        r_surfaces = 1.0 / at_reference["U_value"] - at_reference["R_wall"]
        return {
            "R_wall": r_wall,
            "U_value": 1.0 / (r_wall + r_surfaces),
            "areal_heat_capacity": at_reference["areal_heat_capacity"],
        }
