"""Solar and long-wave boundary conditions of exterior surfaces: small pure functions.

- Solar position (``pvlib.solarposition``), direct normal irradiance by closure
  from global and diffuse horizontal irradiance, and transposition to a plane of
  any tilt (``pvlib.irradiance``: isotropic, Hay–Davies or Perez sky diffuse,
  ground-reflected with an albedo), returned by component so that a window can
  weight beam and diffuse light with different incidence-angle modifiers.
- Incidence-angle modifiers of clear double glazing (transmittance) and of
  one pane's absorptance, and their hemispherical (diffuse) average.
- Effective sky temperature: from measured horizontal infrared irradiance, from
  the Berdahl & Martin clear-sky emissivity (dew point), or from Swinbank's
  formula (air temperature only).
- Exterior convective coefficient as a function of wind speed (ISO 6946).

Angles are in degrees, azimuths clockwise from north (pvlib's convention),
temperatures in °C, irradiances in W/m².
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd
import pvlib
from scipy.constants import Stefan_Boltzmann, zero_Celsius

from bayescal.errors import SimulatorError

SKY_MODELS = ("isotropic", "haydavies", "perez")

# Magnus coefficients over water (Alduchov & Eskridge 1996). [-], [°C]
_MAGNUS_A = 17.625
_MAGNUS_B = 243.04


@dataclass(frozen=True)
class PlaneIrradiance:
    """Solar irradiance on one plane, by component, shape ``(n,)`` each.

    Attributes
    ----------
    beam
        Direct (beam) irradiance on the plane. [W/m²]
    sky_diffuse
        Sky-diffuse irradiance on the plane (circumsolar included). [W/m²]
    ground_diffuse
        Ground-reflected irradiance on the plane. [W/m²]
    aoi
        Angle of incidence of the beam on the plane. [°]
    """

    beam: np.ndarray
    sky_diffuse: np.ndarray
    ground_diffuse: np.ndarray
    aoi: np.ndarray

    @property
    def total(self) -> np.ndarray:
        """Global irradiance on the plane. [W/m²]"""
        return self.beam + self.sky_diffuse + self.ground_diffuse


@dataclass(frozen=True)
class SunAndSky:
    """What the transposition needs at each instant, shape ``(n,)`` each.

    Attributes
    ----------
    zenith
        Apparent solar zenith angle. [°]
    azimuth
        Solar azimuth, clockwise from north. [°]
    ghi
        Global horizontal irradiance, negatives set to 0. [W/m²]
    dhi
        Diffuse horizontal irradiance, clipped to ``[0, ghi]``. [W/m²]
    dni
        Direct normal irradiance from closure. [W/m²]
    dni_extra
        Extraterrestrial normal irradiance. [W/m²]
    airmass
        Relative air mass (NaN with the sun below the horizon). [-]
    """

    zenith: npt.ArrayLike
    azimuth: np.ndarray
    ghi: npt.ArrayLike
    dhi: npt.ArrayLike
    dni: np.ndarray
    dni_extra: np.ndarray
    airmass: np.ndarray


def _index(times: np.ndarray) -> pd.DatetimeIndex:
    return pd.DatetimeIndex(np.asarray(times, dtype="datetime64[ns]")).tz_localize("UTC")


def _extra_radiation(times: np.ndarray) -> np.ndarray:
    """Extraterrestrial normal irradiance from the day of year (pvlib, Spencer). [W/m²]"""
    doy = _index(times).day_of_year.to_numpy().astype(float)
    return np.asarray(pvlib.irradiance.get_extra_radiation(doy), dtype=float)


def solar_position(
    times: np.ndarray, latitude: float, longitude: float, altitude: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Apparent solar zenith and azimuth (``pvlib.solarposition``, NREL SPA).

    Parameters
    ----------
    times
        Instants, UTC (``datetime64``), shape ``(n,)``.
    latitude
        Site latitude, north positive. [°]
    longitude
        Site longitude, east positive. [°]
    altitude
        Site altitude above sea level. [m]

    Returns
    -------
    zenith, azimuth
        Apparent zenith angle and azimuth (clockwise from north). [°]
    """
    if not -90.0 <= latitude <= 90.0 or not -180.0 <= longitude <= 360.0:
        raise SimulatorError(
            f"latitude must be in [-90, 90] and longitude in [-180, 360] degrees, "
            f"got latitude={latitude!r}, longitude={longitude!r}"
        )
    pos = pvlib.solarposition.get_solarposition(_index(times), latitude, longitude, altitude)
    return pos["apparent_zenith"].to_numpy(), pos["azimuth"].to_numpy()


def clear_sky(
    times: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
    linke_turbidity: float = 3.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Clear-sky global and diffuse horizontal irradiance (Ineichen–Perez, pvlib).

    For synthetic weather (tests, benchmarks, examples).

    Parameters
    ----------
    times
        Instants, UTC (``datetime64``), shape ``(n,)``.
    latitude
        Site latitude, north positive. [°]
    longitude
        Site longitude, east positive. [°]
    altitude
        Site altitude. [m]
    linke_turbidity
        Linke turbidity factor, constant (3 is a typical European value). [-]

    Returns
    -------
    ghi, dhi
        Global and diffuse horizontal irradiance. [W/m²]
    """
    zenith, _ = solar_position(times, latitude, longitude, altitude)
    airmass = pvlib.atmosphere.get_absolute_airmass(
        pvlib.atmosphere.get_relative_airmass(zenith), pvlib.atmosphere.alt2pres(altitude)
    )
    with np.errstate(divide="ignore", invalid="ignore"):  # sun below the horizon
        cs = pvlib.clearsky.ineichen(
            zenith, airmass, linke_turbidity, altitude=altitude, dni_extra=_extra_radiation(times)
        )
    ghi = np.nan_to_num(np.asarray(cs["ghi"], dtype=float))
    dhi = np.nan_to_num(np.asarray(cs["dhi"], dtype=float))
    return ghi, dhi


def dni_from_closure(ghi: npt.ArrayLike, dhi: npt.ArrayLike, zenith: npt.ArrayLike) -> np.ndarray:
    """Direct normal irradiance ``(ghi - dhi) / cos(zenith)`` (``pvlib.irradiance.dni``).

    Where pvlib declares the closure unreasonable (sun within 2° of the horizon
    or below it, ``dhi > ghi``) the beam is set to zero instead of NaN, so that
    the solar energy lost is at most the few W/m² of a grazing sun.

    Parameters
    ----------
    ghi
        Global horizontal irradiance. [W/m²]
    dhi
        Diffuse horizontal irradiance. [W/m²]
    zenith
        Solar zenith angle. [°]

    Returns
    -------
    numpy.ndarray
        Direct normal irradiance, non-negative. [W/m²]
    """
    dni = pvlib.irradiance.dni(
        pd.Series(np.asarray(ghi, dtype=float)),
        pd.Series(np.asarray(dhi, dtype=float)),
        pd.Series(np.asarray(zenith, dtype=float)),
    ).to_numpy()
    return np.where(np.isfinite(dni), np.maximum(dni, 0.0), 0.0)


def sun_and_sky(
    times: np.ndarray,
    ghi: npt.ArrayLike,
    dhi: npt.ArrayLike,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
) -> SunAndSky:
    """Solar geometry and irradiance components at each instant.

    Parameters
    ----------
    times
        Instants, UTC (``datetime64``), shape ``(n,)``.
    ghi
        Global horizontal irradiance, shape ``(n,)``; small negative night
        readings are set to 0. [W/m²]
    dhi
        Diffuse horizontal irradiance, shape ``(n,)``; clipped to ``[0, ghi]``. [W/m²]
    latitude
        Site latitude, north positive. [°]
    longitude
        Site longitude, east positive. [°]
    altitude
        Site altitude. [m]

    Returns
    -------
    SunAndSky
    """
    g = np.maximum(np.asarray(ghi, dtype=float), 0.0)
    d = np.clip(np.asarray(dhi, dtype=float), 0.0, g)
    if g.shape != np.shape(times) or d.shape != np.shape(times):
        raise SimulatorError(
            f"ghi, dhi and times must have the same shape, got {g.shape}, {d.shape} "
            f"and {np.shape(times)}"
        )
    zenith, azimuth = solar_position(times, latitude, longitude, altitude)
    dni = dni_from_closure(g, d, zenith)
    dni_extra = _extra_radiation(times)
    airmass = np.asarray(pvlib.atmosphere.get_relative_airmass(zenith), dtype=float)
    return SunAndSky(zenith, azimuth, g, d, dni, dni_extra, airmass)


def plane_irradiance(
    surface_tilt: float,
    surface_azimuth: float,
    sky: SunAndSky,
    *,
    albedo: float = 0.2,
    model: str = "haydavies",
) -> PlaneIrradiance:
    """Transpose horizontal irradiance to a plane (``pvlib.irradiance.get_total_irradiance``).

    Parameters
    ----------
    surface_tilt
        Tilt from horizontal: 0 faces up, 90 vertical, 180 faces down. [°]
    surface_azimuth
        Azimuth the plane faces, clockwise from north. [°]
    sky
        Solar geometry and irradiance components, from :func:`sun_and_sky`.
    albedo
        Ground reflectance for the ground-reflected part. [-]
    model
        Sky-diffuse model: ``"isotropic"``, ``"haydavies"`` or ``"perez"``.

    Returns
    -------
    PlaneIrradiance
    """
    if model not in SKY_MODELS:
        raise SimulatorError(f"unknown sky-diffuse model {model!r}; use one of {SKY_MODELS}")
    if not 0.0 <= albedo <= 1.0:
        raise SimulatorError(f"albedo must be in [0, 1], got {albedo!r}")
    if not 0.0 <= surface_tilt <= 180.0:
        raise SimulatorError(f"surface tilt must be in [0, 180] degrees, got {surface_tilt!r}")
    parts = pvlib.irradiance.get_total_irradiance(
        surface_tilt,
        surface_azimuth,
        sky.zenith,
        sky.azimuth,
        sky.dni,
        sky.ghi,
        sky.dhi,
        dni_extra=sky.dni_extra,
        airmass=sky.airmass,
        albedo=albedo,
        model=model,
    )
    aoi = np.asarray(pvlib.irradiance.aoi(surface_tilt, surface_azimuth, sky.zenith, sky.azimuth))

    def clean(x: object) -> np.ndarray:
        arr = np.asarray(x, dtype=float)
        return np.where(np.isfinite(arr), np.maximum(arr, 0.0), 0.0)

    return PlaneIrradiance(
        beam=clean(parts["poa_direct"]),
        sky_diffuse=clean(parts["poa_sky_diffuse"]),
        ground_diffuse=clean(parts["poa_ground_diffuse"]),
        aoi=aoi,
    )


def view_factors(surface_tilt: float) -> tuple[float, float]:
    """View factors of a plane to the sky and to the (infinite, flat) ground.

    Parameters
    ----------
    surface_tilt
        Tilt from horizontal: 0 faces up, 180 faces down. [°]

    Returns
    -------
    f_sky, f_ground
        ``(1 + cos tilt) / 2`` and ``(1 - cos tilt) / 2``. [-]
    """
    c = float(np.cos(np.radians(surface_tilt)))
    return 0.5 * (1.0 + c), 0.5 * (1.0 - c)


def longwave_view_factors(surface_tilt: float, sky_air_split: bool = True) -> tuple[float, float]:
    """Long-wave view factors of a plane to the sky and to surroundings at air temperature.

    The plane sees the sky through ``F_sky = (1 + cos tilt) / 2`` and the ground,
    taken at outside air temperature, through ``F_ground = (1 - cos tilt) / 2``
    (:func:`view_factors`). A sky temperature derived from the horizontal
    long-wave irradiance is a hemispherical average, but the sky near the horizon,
    which is most of what a wall sees, radiates nearly at air temperature. With
    ``sky_air_split`` the sky view is divided as in EnergyPlus (Engineering
    Reference, "Outside Surface Heat Balance", exterior long-wave radiation): the
    fraction ``beta = sqrt(F_sky)`` of the sky view exchanges with the sky
    temperature and ``1 - beta`` of it with the air. A roof keeps its whole sky
    (beta 1); a wall sees 0.354 sky instead of 0.5.

    Parameters
    ----------
    surface_tilt
        Tilt from horizontal: 0 faces up, 180 faces down. [°]
    sky_air_split
        Divide the sky view between sky and air temperature (``False``: the
        whole sky view at the sky temperature).

    Returns
    -------
    f_sky, f_air
        View factor at the sky temperature and view factor at outside air
        temperature (ground, plus the sky near the horizon); they sum to 1. [-]
    """
    f_sky, f_ground = view_factors(surface_tilt)
    beta = float(np.sqrt(f_sky)) if sky_air_split else 1.0
    return beta * f_sky, f_ground + (1.0 - beta) * f_sky


def double_glazing_iam(
    aoi: npt.ArrayLike, n: float = 1.526, extinction: float = 4.0, thickness: float = 0.004
) -> np.ndarray:
    """Incidence-angle modifier of clear double glazing.

    Product of two identical panes' modifiers from Fresnel reflection and
    Bouguer absorption (``pvlib.iam.physical``, De Soto et al. 2006); the
    inter-reflections between the panes are neglected. 1 at normal incidence,
    0 at grazing incidence and beyond 90°.

    Parameters
    ----------
    aoi
        Angle of incidence. [°]
    n
        Refractive index of the glass. [-]
    extinction
        Glazing extinction coefficient. [1/m]
    thickness
        Thickness of one pane. [m]

    Returns
    -------
    numpy.ndarray
        Transmittance relative to normal incidence. [-]
    """
    single = pvlib.iam.physical(np.asarray(aoi, dtype=float), n=n, K=extinction, L=thickness)
    return np.asarray(single, dtype=float) ** 2


def pane_absorptance_iam(aoi: npt.ArrayLike, absorptance: float, n: float = 1.526) -> np.ndarray:
    """Incidence-angle modifier of the solar absorptance of one uncoated pane.

    Fresnel reflection at the faces (unpolarised, refractive index ``n``) and
    Bouguer absorption along the refracted path, with one internal reflection:
    ``a(θ) = (1 - r)(1 - τ)(1 + r τ)``, ``τ = exp(-κ / cos θ_t)``; ``κ`` is
    solved so that ``a(0)`` is the given normal-incidence ``absorptance``. The
    longer path raises the absorptance up to about 60°; reflection makes it fall
    to 0 at grazing incidence. After EnergyPlus's angular properties of an
    uncoated glazing given at normal incidence (Engineering Reference, "Window
    Calculation Module"), simplified: the refractive index is given instead of
    fitted to the reflectance, the two polarisations' reflectances are averaged
    before the slab formula, and the series of internal reflections stops after
    the first (within 0.02 % of the full series per polarisation up to 60°,
    4 % at 80°, for the box's
    pane; ``tests/simulators/test_solar.py``).

    Parameters
    ----------
    aoi
        Angle of incidence. [°]
    absorptance
        Solar absorptance at normal incidence, below ``1 - r(0)``
        (0.957 for ``n`` = 1.526). [-]
    n
        Refractive index of the glass. [-]

    Returns
    -------
    numpy.ndarray
        Absorptance relative to normal incidence (ones where ``absorptance`` is 0). [-]

    Raises
    ------
    SimulatorError
        If ``absorptance`` is outside ``[0, 1 - r(0))``.
    """
    theta = np.radians(np.clip(np.asarray(aoi, dtype=float), 0.0, 90.0))
    r0 = ((n - 1.0) / (n + 1.0)) ** 2
    if not 0.0 <= absorptance < 1.0 - r0:
        raise SimulatorError(
            f"pane absorptance must be in [0, {1.0 - r0:.3f}) for a refractive index of "
            f"{n}, got {absorptance!r}"
        )
    if absorptance == 0.0:
        return np.ones_like(theta)
    # r0 u^2 + (1 - r0) u - (1 - a / (1 - r0)) = 0 for u = tau(0).
    c = 1.0 - absorptance / (1.0 - r0)
    tau0 = (-(1.0 - r0) + np.sqrt((1.0 - r0) ** 2 + 4.0 * r0 * c)) / (2.0 * r0)
    kappa = -np.log(tau0)
    cos_i = np.cos(theta)
    sin_t = np.sin(theta) / n
    cos_t = np.sqrt(1.0 - sin_t**2)
    with np.errstate(divide="ignore", invalid="ignore"):
        r_s = ((cos_i - n * cos_t) / (cos_i + n * cos_t)) ** 2
        r_p = ((cos_t - n * cos_i) / (cos_t + n * cos_i)) ** 2
    r = 0.5 * (r_s + r_p)
    tau = np.exp(-kappa / cos_t)
    a = (1.0 - r) * (1.0 - tau) * (1.0 + r * tau)
    return np.asarray(a / absorptance, dtype=float)


def hemispherical_average(iam: Callable[[np.ndarray], np.ndarray], nodes: int = 64) -> float:
    """Diffuse (isotropic hemispherical) average of an incidence-angle modifier.

    ``2 ∫_0^{π/2} iam(θ) cos θ sin θ dθ`` by Gauss–Legendre quadrature.

    Parameters
    ----------
    iam
        Modifier as a function of the incidence angle in degrees. [-]
    nodes
        Quadrature nodes.

    Returns
    -------
    float
        Average modifier for isotropic diffuse light. [-]
    """
    x, w = np.polynomial.legendre.leggauss(nodes)
    theta = 0.25 * np.pi * (x + 1.0)
    values = iam(np.degrees(theta)) * np.cos(theta) * np.sin(theta)
    return float(2.0 * 0.25 * np.pi * np.sum(w * values))


def sky_temperature_from_ir(ir_horizontal: npt.ArrayLike) -> np.ndarray:
    """Effective (black-body) sky temperature from horizontal infrared irradiance.

    Parameters
    ----------
    ir_horizontal
        Long-wave irradiance on a horizontal plane from the sky. [W/m²]

    Returns
    -------
    numpy.ndarray
        ``(ir / sigma)^(1/4)``. [°C]
    """
    ir = np.asarray(ir_horizontal, dtype=float)
    if np.any(ir <= 0):
        raise SimulatorError(
            f"ir_horizontal must be positive, got minimum {float(np.min(ir))!r} W/m²",
            hint="check the column's unit and sign (downwelling long-wave, about 200-400 W/m²)",
        )
    return (ir / Stefan_Boltzmann) ** 0.25 - zero_Celsius


def dew_point(temp_air: npt.ArrayLike, relative_humidity: npt.ArrayLike) -> np.ndarray:
    """Dew-point temperature by the Magnus formula (Alduchov & Eskridge 1996).

    Parameters
    ----------
    temp_air
        Air temperature. [°C]
    relative_humidity
        Relative humidity. [%]

    Returns
    -------
    numpy.ndarray
        Dew-point temperature. [°C]
    """
    rh = np.asarray(relative_humidity, dtype=float)
    if np.any(rh <= 0) or np.any(rh > 105):
        raise SimulatorError(
            f"relative_humidity must be in (0, 100] %, got range "
            f"[{float(np.min(rh))!r}, {float(np.max(rh))!r}]",
            hint="give relative humidity in percent, not as a fraction",
        )
    t = np.asarray(temp_air, dtype=float)
    gamma = np.log(np.minimum(rh, 100.0) / 100.0) + _MAGNUS_A * t / (_MAGNUS_B + t)
    return _MAGNUS_B * gamma / (_MAGNUS_A - gamma)


def sky_temperature_berdahl_martin(
    temp_air: npt.ArrayLike, relative_humidity: npt.ArrayLike
) -> np.ndarray:
    """Clear-sky temperature from the Berdahl & Martin (1984) emissivity.

    ``eps_sky = 0.711 + 0.56 (T_dp/100) + 0.73 (T_dp/100)^2`` with the dew point
    ``T_dp`` in °C, and ``T_sky = eps_sky^(1/4) T_air`` (kelvin). Clouds are not
    represented: under overcast skies this underestimates the sky temperature.

    Parameters
    ----------
    temp_air
        Air temperature. [°C]
    relative_humidity
        Relative humidity. [%]

    Returns
    -------
    numpy.ndarray
        Effective sky temperature. [°C]
    """
    tdp = dew_point(temp_air, relative_humidity) / 100.0
    eps_sky = 0.711 + 0.56 * tdp + 0.73 * tdp**2
    t_k = np.asarray(temp_air, dtype=float) + zero_Celsius
    return eps_sky**0.25 * t_k - zero_Celsius


def sky_temperature_swinbank(temp_air: npt.ArrayLike) -> np.ndarray:
    """Clear-sky temperature from air temperature alone (Swinbank 1963).

    ``T_sky = 0.0552 T_air^1.5`` (kelvin).

    Parameters
    ----------
    temp_air
        Air temperature. [°C]

    Returns
    -------
    numpy.ndarray
        Effective sky temperature. [°C]
    """
    t_k = np.asarray(temp_air, dtype=float) + zero_Celsius
    return 0.0552 * t_k**1.5 - zero_Celsius


def exterior_convection(wind_speed: npt.ArrayLike, a: float = 4.0, b: float = 4.0) -> np.ndarray:
    """Exterior convective heat-transfer coefficient ``h_c = a + b v``.

    The defaults are ISO 6946:2017 (annex C), ``h_c = 4 + 4 v``.

    Parameters
    ----------
    wind_speed
        Wind speed; negative readings are set to 0. [m/s]
    a
        Still-air (natural convection) part. [W/(m²·K)]
    b
        Wind sensitivity. [J/(m³·K)]

    Returns
    -------
    numpy.ndarray
        Convective coefficient. [W/(m²·K)]
    """
    return a + b * np.maximum(np.asarray(wind_speed, dtype=float), 0.0)
