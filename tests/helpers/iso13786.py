"""Exact references for 1-D conduction through layered walls (test helpers).

Independent of the code under test: layers are plain tuples
``(thickness [m], conductivity [W/(m·K)], density [kg/m³], specific heat [J/(kg·K)])``.

- EN ISO 13786 (Annex C) heat transfer matrices, evaluated at any complex
  Laplace variable ``s`` (``s = i omega`` gives the periodic response);
- step and ramp responses by numerical inversion of the Laplace transform
  (fixed Talbot contour, Abate & Valkó 2004, Int. J. Numer. Meth. Eng. 60);
- the Fourier-series solution for a single homogeneous slab.

Sign convention: the wall runs from side 1 to side 2, the state at a plane is
``(temperature, heat flux)`` with the flux positive from side 1 to side 2; the
matrix ``Z`` maps the state at side 1 to the state at side 2 (``det Z = 1``).
With side 1 outside, the inside-surface flux towards the room caused by the
outside temperature is ``Y12 theta_1`` with ``Y12 = -1 / Z12``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

LayerTuple = tuple[float, float, float, float]


def layer_matrix(layer: LayerTuple, s: np.ndarray) -> np.ndarray:
    """Transfer matrix of one homogeneous layer, shape ``(2, 2) + s.shape``.

    Parameters
    ----------
    layer
        ``(thickness [m], k [W/(m·K)], rho [kg/m³], c [J/(kg·K)])``.
    s
        Laplace variable (``i omega`` for the periodic case). [1/s]
    """
    d, k, rho, c = layer
    kappa = np.sqrt(np.asarray(s, dtype=complex) * rho * c / k)
    x = kappa * d
    ch, sh = np.cosh(x), np.sinh(x)
    return np.array([[ch, -sh / (k * kappa)], [-k * kappa * sh, ch]])


def resistance_matrix(resistance: float, s: np.ndarray) -> np.ndarray:
    """Transfer matrix of a surface resistance ``[[1, -R], [0, 1]]``. [m²·K/W]"""
    one = np.ones_like(np.asarray(s, dtype=complex))
    return np.array([[one, -resistance * one], [0 * one, one]])


def wall_matrix(
    layers: Sequence[LayerTuple], s: np.ndarray, r1: float = 0.0, r2: float = 0.0
) -> np.ndarray:
    """Matrix from side 1 (surface resistance ``r1``) to side 2 (``r2``).

    ``layers`` are listed from side 1 to side 2; ``Z = R2 Z_N ... Z_1 R1``.
    """
    total = resistance_matrix(r1, s)
    for layer in layers:
        total = np.einsum("ij...,jk...->ik...", layer_matrix(layer, s), total)
    return np.einsum("ij...,jk...->ik...", resistance_matrix(r2, s), total)


def surface_admittance(
    layers: Sequence[LayerTuple], omega: np.ndarray, r1: float = 0.0, r2: float = 0.0
) -> np.ndarray:
    """Admittance of side 1 with side 2 held: flux into the wall at side 1 per unit
    temperature beyond the resistance ``r1``, with ``r2`` before the held side. [W/(m²K)]

    Transmission-line recursion with ``tanh``, stable at any frequency
    ``omega`` [rad/s] (the matrix product overflows at high frequencies).
    """
    s = 1j * np.asarray(omega, dtype=float)
    admittance = np.full(s.shape, np.inf if r2 == 0 else 1 / r2, dtype=complex)
    for d, k, rho, c in reversed(layers):
        z0 = k * np.sqrt(s * rho * c / k)
        t = np.tanh(z0 / k * d)
        if np.isinf(admittance).any():  # held face right behind this layer
            admittance = z0 / t
        else:
            admittance = z0 * (admittance + z0 * t) / (z0 + admittance * t)
    return admittance / (1 + r1 * admittance)


def sampled_response(
    transfer: Callable[[np.ndarray], np.ndarray], omega: float, step: float, images: int
) -> complex:
    """Response at the sample instants to ``exp(i omega t)`` sampled every ``step``
    [s] and interpolated linearly (the simulators' time convention).

    The linear interpolant contains the images ``omega + 2 pi j / step`` with
    weights ``sinc²``; sampling the response folds them back onto ``omega``:
    ``sum_j sinc²(omega_j step / 2 pi) transfer(omega_j)``, ``|j| <= images``.
    """
    omegas = omega + 2 * np.pi / step * np.arange(-images, images + 1)
    weights = np.sinc(omegas * step / (2 * np.pi)) ** 2
    return complex(np.sum(weights * transfer(omegas)))


def periodic_properties(
    layers: Sequence[LayerTuple], period: float, r1: float = 0.0, r2: float = 0.0
) -> dict[str, float]:
    """EN ISO 13786 periodic properties, side 1 taken as the inside.

    Returns U [W/(m²K)], abs(Y12) [W/(m²K)], time shift of Y12 [h], decrement
    factor [-] and the areal heat capacity kappa1 of side 1 [kJ/(m²K)].
    """
    omega = 2 * np.pi / period
    z = wall_matrix(layers, np.array(1j * omega), r1, r2)
    y12 = -1 / z[0, 1]
    u_value = 1 / (r1 + r2 + sum(d / k for d, k, _, _ in layers))
    return {
        "U": u_value,
        "abs_Y12": float(abs(y12)),
        "time_shift_h": float(np.angle(y12)) * period / (2 * np.pi) / 3600,
        "decrement": float(abs(y12)) / u_value,
        "kappa1_kJ": period / (2 * np.pi) * float(abs((z[0, 0] - 1) / z[0, 1])) / 1000,
    }


def talbot(transform: Callable[[np.ndarray], np.ndarray], t: float, terms: int = 32) -> float:
    """Inverse Laplace transform at ``t > 0`` by the fixed Talbot contour.

    With ``terms = 32`` the discretisation error is far below the double
    precision round-off, which is amplified by about ``exp(0.4 terms)``.
    """
    r = 2 * terms / (5 * t)
    theta = np.arange(1, terms) * np.pi / terms
    cot = 1 / np.tan(theta)
    s = r * theta * (cot + 1j)
    sigma = theta + (theta * cot - 1) * cot
    first = 0.5 * np.real(transform(np.array([r + 0j]))[0]) * np.exp(r * t)
    rest = np.real(np.exp(t * s) * transform(s) * (1 + 1j * sigma)).sum()
    return float(r / terms * (first + rest))


def step_transmittance(
    layers: Sequence[LayerTuple], t: float, r1: float = 0.0, r2: float = 0.0
) -> float:
    """Flux leaving side 2 after a unit step of the side-1 temperature. [W/m² per K]

    Inverse Laplace transform of ``-1 / (s Z12(s))`` at time ``t``. [s]
    """
    return talbot(lambda s: -1 / (s * wall_matrix(layers, s, r1, r2)[0, 1]), t)


def ramp_transmittance(
    layers: Sequence[LayerTuple], t: float, rise: float, r1: float = 0.0, r2: float = 0.0
) -> float:
    """As :func:`step_transmittance` for a linear rise from 0 to 1 over ``rise``. [s]

    ``(I(t) - I(t - rise)) / rise`` where ``I`` is the integral of the step
    response, the inverse transform of ``-1 / (s² Z12(s))``.
    """

    def integral(time: float) -> float:
        if time <= 0:
            return 0.0
        return talbot(lambda s: -1 / (s**2 * wall_matrix(layers, s, r1, r2)[0, 1]), time)

    return (integral(t) - integral(t - rise)) / rise


def slab_step_flux(layer: LayerTuple, t: float, rise: float = 0.0, terms: int = 2000) -> float:
    """Single slab, face 1 raised by 1 K at ``t = 0`` (linearly over ``rise`` [s]),
    face 2 held: flux leaving face 2. [W/m²]

    Fourier series ``q = k/d (1 + 2 sum (-1)^n exp(-n² pi² a t / d²))``,
    integrated term by term over the rise when ``rise > 0``.
    """
    d, k, rho, c = layer
    rate = (np.arange(1, terms + 1) * np.pi / d) ** 2 * k / (rho * c)
    sign = (-1.0) ** np.arange(1, terms + 1)

    def integral(time: float) -> float:  # integral of q from 0 to time
        if time <= 0:
            return 0.0
        return k / d * (time + 2 * np.sum(sign * -np.expm1(-rate * time) / rate))

    if rise == 0:
        return float(k / d * (1 + 2 * np.sum(sign * np.exp(-rate * t))))
    return (integral(t) - integral(t - rise)) / rise
