"""The sun in the built-in test box: the glazing's absorption and where transmitted light goes.

Pure functions of :mod:`bayescal.simulators.box` (its module docstring, "Window",
states the model): the solar power the glazing absorbs from outside, the face
each ray of the transmitted beam meets first, and the integrating-sphere
balance of the light the inside faces reflect.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import numpy as np

from bayescal.simulators import solar

__all__ = [
    "WINDOW_MODELS",
    "beam_first_hit",
    "diffuse_absorptance",
    "interior_solar",
    "pane_absorptance",
    "window_absorbed",
    "window_solar",
]

WINDOW_MODELS = ("transmittance", "layers")
"""``window_model`` of :class:`~bayescal.simulators.box.TestBox`."""

_GRID = 12  # rays across each side of the glazing


class _Faces(Protocol):
    """What :func:`window_solar` and :func:`interior_solar` read of the box's geometry."""

    @property
    def area(self) -> np.ndarray: ...
    @property
    def window_area(self) -> float: ...
    @property
    def solar_share(self) -> np.ndarray: ...


def window_solar(
    values: Mapping[str, float],
    geo: _Faces,
    front: solar.PlaneIrradiance,
    sky: solar.SunAndSky,
    window_azimuth: float,
    window_model: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sun through the window of the box (module docstring of
    :mod:`~bayescal.simulators.box`, "Window").

    Parameters
    ----------
    values
        The box's constants and parameters.
    geo
        Its geometry.
    front
        Irradiance on the window's plane, shape ``(n,)`` each.
    sky
        The sun's position (for where the beam falls).
    window_azimuth
        Azimuth the window faces. [°]
    window_model
        One of :data:`WINDOW_MODELS`.

    Returns
    -------
    solar_in, returned, absorbed
        Transmitted power absorbed at each face's inside surface, shape
        ``(n, 6)`` [W]; transmitted power that reaches the glazing again from
        inside [W]; power absorbed in the glazing per glazed area, from
        outside and inside, 0 at the first instant (a steady state without
        sun) [W/m²].
    """
    t_w, area = values["t_w"], geo.window_area
    beam = t_w * area * solar.double_glazing_iam(front.aoi) * front.beam
    t_diffuse = t_w * solar.hemispherical_average(solar.double_glazing_iam)
    diffuse = area * t_diffuse * (front.sky_diffuse + front.ground_diffuse)
    if window_model == "transmittance":
        zero = np.zeros_like(beam)
        return (beam + diffuse)[:, None] * geo.solar_share[None, :], zero, zero.copy()
    first_hit = beam_first_hit(
        np.asarray(sky.zenith),
        sky.azimuth,
        window_azimuth,
        values["side"],
        values["glazed_side"],
        geo.solar_share,
    )
    a_diffuse = diffuse_absorptance(pane_absorptance(values))
    solar_in, sent_out, glazing = interior_solar(
        values, geo, beam, diffuse, first_hit, t_diffuse, a_diffuse
    )
    absorbed = window_absorbed(values, front, a_diffuse) + glazing / area
    absorbed[0] = 0.0
    return solar_in, sent_out + glazing, absorbed


def pane_absorptance(values: Mapping[str, float]) -> float:
    """Normal-incidence solar absorptance of the glazing: ``1 - t_w - reflectance_w``
    (:class:`~bayescal.simulators.box.TestBox` refuses a negative one). [-]"""
    return max(0.0, 1.0 - values["t_w"] - values["reflectance_w"])


def diffuse_absorptance(a_w: float) -> float:
    """The glazing's absorptance for isotropic diffuse light. [-]"""
    if a_w == 0.0:
        return 0.0
    return a_w * solar.hemispherical_average(lambda aoi: solar.pane_absorptance_iam(aoi, a_w))


def window_absorbed(
    values: Mapping[str, float], front: solar.PlaneIrradiance, a_diffuse: float
) -> np.ndarray:
    """Solar power absorbed in the glazing from outside, per glazed area, given its
    absorptance for diffuse light ``a_diffuse`` (:func:`diffuse_absorptance`). [W/m²]"""
    a_w = pane_absorptance(values)
    if a_w == 0.0:
        return np.zeros_like(front.beam)
    beam = a_w * solar.pane_absorptance_iam(front.aoi, a_w) * front.beam
    return beam + a_diffuse * (front.sky_diffuse + front.ground_diffuse)


def beam_first_hit(
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window_azimuth: float,
    side: float,
    glazed_side: float,
    diffuse_share: np.ndarray,
) -> np.ndarray:
    """Share of the transmitted beam that each face meets first, shape ``(n, 6)``.

    Rays enter through a ``_GRID`` x ``_GRID`` lattice of points of the glazed
    square (centred in the front face of the cube of inner edge ``side``) along
    the sun's direction; each is counted on the face it reaches first (sides,
    back or floor; the front cannot be reached, nor the roof by a sun above the
    horizon). Where the sun is behind the window plane (no beam enters), the
    shares are ``diffuse_share``, those of the diffuse light.
    Faces in the order of :data:`bayescal.simulators.box.FACES`.

    Parameters
    ----------
    zenith, azimuth
        Solar zenith and azimuth (clockwise from north), shape ``(n,)``. [°]
    window_azimuth
        Azimuth the window faces. [°]
    side, glazed_side
        Inner edge of the box and edge of the glazed square. [m]
    diffuse_share
        Shares of the faces where no beam enters, shape ``(6,)``. [-]
    """
    z = np.radians(np.asarray(zenith, dtype=float))[:, None]
    rel = np.radians(np.asarray(azimuth, dtype=float) - window_azimuth)[:, None]
    # Light direction: u across the front towards side_cw, v inwards, z up.
    du, dv, dz = -np.sin(z) * np.sin(rel), np.sin(z) * np.cos(rel), -np.cos(z)
    offsets = (side - glazed_side) / 2.0 + glazed_side * (np.arange(_GRID) + 0.5) / _GRID
    u, h = (g.ravel()[None, :] for g in np.meshgrid(offsets, offsets))
    enters = (dv > 1e-9) & (dz < -1e-9)
    shape = (z.shape[0], u.shape[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        steps = np.stack(
            [
                np.broadcast_to(np.where(du > 1e-12, (side - u) / du, np.inf), shape),  # cw
                np.broadcast_to(np.where(dv > 1e-9, side / dv, np.inf), shape),  # back
                np.broadcast_to(np.where(du < -1e-12, -u / du, np.inf), shape),  # ccw
                np.broadcast_to(np.where(dz < -1e-9, -h / dz, np.inf), shape),  # floor
            ]
        )
    first = np.argmin(steps, axis=0)  # (n, rays)
    shares = np.zeros((z.shape[0], 6))
    for k, face in enumerate((1, 2, 3, 5)):
        shares[:, face] = (first == k).mean(axis=1)
    return np.where(enters, shares, np.asarray(diffuse_share, dtype=float)[None, :])


def interior_solar(
    values: Mapping[str, float],
    geo: _Faces,
    beam: np.ndarray,
    diffuse: np.ndarray,
    first_hit: np.ndarray,
    t_diffuse: float,
    a_diffuse: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the transmitted solar power goes.

    The transmitted ``beam`` first meets the faces in the shares ``first_hit``
    (:func:`beam_first_hit`), the transmitted ``diffuse`` light the five faces
    opposite and beside the window in proportion to their areas
    (``geo.solar_share``); they absorb ``absorptivity_in`` of it. The rest is
    reflected diffusely and shared as in an integrating sphere between the
    faces' opaque areas (absorbing ``absorptivity_in``) and the glazing, which
    sends back out its diffuse transmittance ``t_diffuse`` and absorbs its
    diffuse absorptance ``a_diffuse``. [W]

    Returns
    -------
    absorbed, sent_out, glazing
        Absorbed at each face's inside surface, shape ``(n, 6)``; sent back out
        through the glazing and absorbed in it, shape ``(n,)`` each.
    """
    alpha = values["absorptivity_in"]
    t_d, a_d = t_diffuse, a_diffuse
    sink_faces = alpha * geo.area.sum()
    sink_window = geo.window_area * (t_d + a_d)
    to_faces = sink_faces / (sink_faces + sink_window) if sink_faces + sink_window > 0 else 1.0
    first = beam[:, None] * first_hit + diffuse[:, None] * geo.solar_share[None, :]
    reflected = (1.0 - alpha) * (beam + diffuse)
    spread = (reflected * to_faces)[:, None] * (geo.area / geo.area.sum())[None, :]
    to_window = reflected * (1.0 - to_faces)
    share_out = t_d / (t_d + a_d) if t_d + a_d > 0 else 0.0
    return alpha * first + spread, to_window * share_out, to_window * (1.0 - share_out)
