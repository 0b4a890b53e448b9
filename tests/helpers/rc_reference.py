"""Analytic solutions of the one-node RC model used by the simulator-adapter tests.

``C dT/dt = (u(t) - T) / R`` with ``T(0) = T0`` and heat flux ``q = (u - T) / R``.
For an input that is linear over a step of length ``h`` (slope ``b``), the exact
solution is ``T(h) = u(h) - b tau + (T(0) - u(0) + b tau) exp(-h / tau)``,
``tau = R C``; for an input held constant it is the same with ``b = 0``.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def rc_exact(
    u: np.ndarray, step: float, r: float, c: float, t0: float, *, hold: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Exact node temperature [°C] and heat flux [W/m²] at the sample instants.

    Parameters
    ----------
    u
        Input temperature at the samples. [°C]
    step
        Time step. [s]
    r
        Thermal resistance. [m²K/W]
    c
        Heat capacity. [J/(m²K)]
    t0
        Initial node temperature. [°C]
    hold
        If true the input is held constant over each step (zero-order hold),
        otherwise it is linear between samples.
    """
    tau = r * c
    decay = np.exp(-step / tau)
    temp = np.empty_like(u, dtype=float)
    temp[0] = t0
    for i in range(len(u) - 1):
        b = 0.0 if hold else (u[i + 1] - u[i]) / step
        end = u[i] + b * step
        temp[i + 1] = end - b * tau + (temp[i] - u[i] + b * tau) * decay
    return temp, (u - temp) / r


def rc_numerical(
    u: np.ndarray, step: float, r: float, c: float, t0: float
) -> tuple[np.ndarray, np.ndarray]:
    """The same for a linear input, by adaptive Runge-Kutta restarted at every sample.

    Each segment has a smooth (linear) input, so DOP853 at rtol = atol = 1e-12
    reaches ~1e-11 K per segment. Independent of :func:`rc_exact`.
    """
    temp = np.empty_like(u, dtype=float)
    temp[0] = t0
    for i in range(len(u) - 1):
        slope = (u[i + 1] - u[i]) / step
        sol = solve_ivp(
            lambda s, y, i=i, slope=slope: (u[i] + slope * s - y) / (r * c),
            (0.0, step),
            [temp[i]],
            method="DOP853",
            rtol=1e-12,
            atol=1e-12,
        )
        temp[i + 1] = sol.y[0, -1]
    return temp, (u - temp) / r
