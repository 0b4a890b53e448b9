"""The built-in multilayer wall against exact solutions (method.md section 8).

References come from ``iso13786.py`` (EN ISO 13786 transfer matrices, fixed
Talbot inversion, Fourier series), which is itself checked against the table
of method.md section 8 here.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy.linalg import solve_banded

import iso13786 as iso
from bayescal.errors import SimulatorError
from bayescal.simulators.base import Forcing, Simulator
from bayescal.simulators.fvm import Layer
from bayescal.simulators.wall import MultilayerWall
from paths import SHARED_DATA

GF = (0.027, 0.0316, 116.6, 840.0)  # glass-fibre board: d, k, rho, c
CB = (0.15, 0.12, 552.0, 800.0)  # aerated concrete
PAPER = [GF, CB, GF]
TWIN = [  # Annex 58 Twin House west wall, outside to inside (shared/data/README.md)
    (0.01, 0.8, 1200.0, 1000.0),
    (0.08, 0.04, 80.0, 840.0),
    (0.03, 1.0, 1200.0, 1000.0),
    (0.30, 0.22, 800.0, 1000.0),
    (0.01, 1.0, 1200.0, 1000.0),
]
HALF_HOUR = 1800.0
DAY = 86400.0
HOUR = 3600.0
SURFACE = ("temp_surf_out", "temp_surf_in")
AIR = ("temp_air_out", "temp_air_in")
DATA = SHARED_DATA


def paper_layers() -> list[Layer]:
    return [Layer("fb_out", *GF), Layer("concrete", *CB), Layer("fb_in", *GF)]


def u_value(layers: list[tuple[float, float, float, float]], r_extra: float = 0.0) -> float:
    return 1 / (r_extra + sum(d / k for d, k, _, _ in layers))


def drive(names: tuple[str, ...], outside: np.ndarray, inside: np.ndarray, step: float) -> Forcing:
    return Forcing(step, {names[0]: outside, names[1]: inside})


def harmonic(series: np.ndarray, omega: float, step: float, samples: int) -> complex:
    """Complex amplitude c of ``Re(c exp(i omega t))`` fitted over the last samples."""
    t = np.arange(series.size)[-samples:] * step
    basis = np.column_stack([np.cos(omega * t), -np.sin(omega * t), np.ones(samples)])
    coef = np.linalg.lstsq(basis, series[-samples:], rcond=None)[0]
    return complex(coef[0], coef[1])


def assert_harmonic(got: complex, expected: complex, period: float) -> None:
    # Requirement: amplitude within 0.5 %, phase within 2 minutes.
    assert abs(got) / abs(expected) - 1 == pytest.approx(0, abs=5e-3)
    shift = np.angle(got / expected) * period / (2 * np.pi)
    assert abs(shift) < 120.0


# ----------------------------------------------------------- reference helpers


@pytest.mark.parametrize(
    ("r_si", "r_se", "table"),
    [
        (0.13, 0.04, (0.31961, 0.096156, -7.994, 0.30086, 11.632)),
        (0.0, 0.0, (0.33797, 0.109436, -7.804, 0.32381, 12.858)),
    ],
)
def test_iso13786_helper_matches_method_table(r_si, r_se, table):
    got = iso.periodic_properties(PAPER[::-1], DAY, r_si, r_se)  # side 1 = inside
    keys = ("U", "abs_Y12", "time_shift_h", "decrement", "kappa1_kJ")
    for key, value in zip(keys, table, strict=True):
        decimals = len(str(value).split(".")[1])
        # The table is rounded to the digits shown: half a unit of the last digit.
        assert got[key] == pytest.approx(value, abs=0.5 * 10.0**-decimals + 1e-12), key


def test_talbot_step_response_matches_method_table():
    table = {1: 2.5e-5, 2: 0.003070, 4: 0.034726, 6: 0.080734, 8: 0.124711, 12: 0.194072}
    table |= {24: 0.294472, 48: 0.334000, 72: 0.337606, 120: 0.337965}
    for hours, value in table.items():
        # Rounded to 6 decimals in the table.
        assert iso.step_transmittance(PAPER, hours * HOUR) == pytest.approx(value, abs=5e-7)


def test_talbot_and_fourier_series_agree_for_a_slab():
    table = {2: 0.172702, 6: 0.678169, 12: 0.790715, 24: 0.799946}
    for hours, value in table.items():
        talbot = iso.step_transmittance([CB], hours * HOUR)
        series = iso.slab_step_flux(CB, hours * HOUR)
        # Two independent exact methods: agree far below the test tolerances.
        assert talbot == pytest.approx(series, abs=1e-9)
        assert series == pytest.approx(value, abs=5e-7)  # table rounded to 6 decimals
        ramp_t = iso.ramp_transmittance([CB], hours * HOUR, HALF_HOUR)
        assert ramp_t == pytest.approx(iso.slab_step_flux(CB, hours * HOUR, HALF_HOUR), abs=1e-9)


def test_stable_admittance_matches_transfer_matrix():
    omega = 2 * np.pi / DAY * np.array([1.0, 10.0, 100.0])
    for r1, r2 in [(0.0, 0.0), (0.04, 0.13)]:
        z = iso.wall_matrix(PAPER, 1j * omega, r1, r2)
        # Same quantity by two formulas; only round-off differs.
        np.testing.assert_allclose(
            iso.surface_admittance(PAPER, omega, r1, r2), -z[0, 0] / z[0, 1], rtol=1e-10
        )


# ----------------------------------------------------------------- steady state


def test_steady_state_surface_to_surface_is_u_value():
    wall = MultilayerWall(
        paper_layers(),
        outputs=("heat_flux_in", "heat_flux_out", "temp_interface_1", "heat_flux_interface_2"),
    )
    n = 20 * 48  # 20 days: the slowest mode (about 10 h) has long decayed
    outside = np.full(n, -5.0)
    outside[0] = 10.0
    out = wall.simulate({}, drive(SURFACE, outside, np.full(n, 20.0), HALF_HOUR))
    u = u_value(PAPER)
    assert u == pytest.approx(0.33797, abs=5e-6)  # method.md, 5 decimals
    # Steady state is exact on any mesh: only round-off remains.
    assert out["heat_flux_in"][0] == pytest.approx(u * (10 - 20), rel=1e-10)
    for name in ("heat_flux_in", "heat_flux_out", "heat_flux_interface_2"):
        assert out[name][-1] == pytest.approx(u * (-5 - 20), rel=1e-9)
    expected_t1 = -5 - u * (-5 - 20) * GF[0] / GF[1]
    assert out["temp_interface_1"][-1] == pytest.approx(expected_t1, rel=1e-9)


def test_steady_state_air_to_air_is_u_value():
    wall = MultilayerWall(
        paper_layers(),
        boundary="air",
        outputs=("heat_flux_in", "heat_flux_out", "temp_surf_in", "temp_surf_out"),
    )
    out = wall.simulate({}, drive(AIR, np.full(3, 0.0), np.full(3, 20.0), HALF_HOUR))
    u = u_value(PAPER, 0.13 + 0.04)
    assert u == pytest.approx(0.31961, abs=5e-6)  # method.md, 5 decimals
    # Exact in steady state up to round-off.
    np.testing.assert_allclose(out["heat_flux_in"], -20 * u, rtol=1e-10)
    np.testing.assert_allclose(out["heat_flux_out"], -20 * u, rtol=1e-10)
    np.testing.assert_allclose(out["temp_surf_in"], 20 - 20 * u * 0.13, rtol=1e-10)
    np.testing.assert_allclose(out["temp_surf_out"], 20 * u * 0.04, rtol=1e-9)


def test_absorbed_solar_adds_its_steady_share_to_the_inside_flux():
    alpha, irradiance = 0.6, 400.0
    wall = MultilayerWall(
        paper_layers(), boundary="air", solar_absorptance=alpha, outputs=("heat_flux_in",)
    )
    assert wall.input_names == ("temp_air_out", "temp_air_in", "poa_global_out")
    n = 20 * 48
    solar = np.full(n, irradiance)
    solar[0] = 0.0
    forcing = Forcing(
        HALF_HOUR,
        {"temp_air_out": np.zeros(n), "temp_air_in": np.full(n, 20.0), "poa_global_out": solar},
    )
    q = wall.simulate({}, forcing)["heat_flux_in"]
    u = u_value(PAPER, 0.17)
    # Sol-air temperature: alpha G R_se adds to the outside air temperature.
    assert q[0] == pytest.approx(-20 * u, rel=1e-10)
    assert q[-1] == pytest.approx(-20 * u + alpha * irradiance * 0.04 * u, rel=1e-9)


# ------------------------------------------------------------ periodic response


@pytest.mark.parametrize(("boundary", "r_se", "r_si"), [("surface", 0, 0), ("air", 0.04, 0.13)])
def test_periodic_response_matches_iso13786(boundary, r_se, r_si):
    outputs = ("heat_flux_in", "heat_flux_out", "temp_interface_1", "heat_flux_interface_1")
    wall = MultilayerWall(paper_layers(), boundary=boundary, outputs=outputs)
    omega = 2 * np.pi / DAY
    n = 10 * 48 + 1  # ten days: the start-up transient (slowest mode ~10 h) is gone
    t = np.arange(n) * HALF_HOUR
    names = SURFACE if boundary == "surface" else AIR
    out = wall.simulate({}, drive(names, np.cos(omega * t), np.zeros(n), HALF_HOUR))
    z = iso.wall_matrix(PAPER, np.array(1j * omega), r_se, r_si)
    first = iso.wall_matrix(PAPER[:1], np.array(1j * omega), r_se, 0.0)
    q_out = -z[0, 0] / z[0, 1]
    # Linear interpolation between half-hourly samples scales the 24 h harmonic by
    # sinc² (0.14 %); the images it creates at periods <= 30 min do not reach the
    # inside or the first interface measurably.
    gain = np.sinc(HALF_HOUR / DAY) ** 2
    expected = {
        "heat_flux_in": -1 / z[0, 1] * gain,
        "temp_interface_1": (first[0, 0] + first[0, 1] * q_out) * gain,
        "heat_flux_interface_1": (first[1, 0] + first[1, 1] * q_out) * gain,
        # The outside admittance grows with frequency, so the images fold back onto
        # the samples and are summed (1e5 images leave a tail of about 1e-5).
        "heat_flux_out": iso.sampled_response(
            lambda w: iso.surface_admittance(PAPER, w, r_se, r_si), omega, HALF_HOUR, 100_000
        ),
    }
    for name, value in expected.items():
        assert_harmonic(harmonic(out[name], omega, HALF_HOUR, 48), value, DAY)


@pytest.mark.parametrize("step", [600.0, 1800.0, 3600.0])
@pytest.mark.parametrize("tolerance", [1e-1, 1e-2, 1e-3])
@pytest.mark.parametrize("construction", ["paper", "twin"])
def test_tolerance_bounds_the_periodic_response_error(construction, tolerance, step):
    layers_t = PAPER if construction == "paper" else TWIN
    layers = [Layer(f"layer{i}", *lt) for i, lt in enumerate(layers_t)]
    mesh = MultilayerWall(layers, tolerance=tolerance).propagator({}, step).mesh
    for period in 2 * step * np.geomspace(1, 1000, 25):
        omega = 2 * np.pi / period
        got = _discrete_flux_response(mesh.conductance, mesh.capacity, omega)
        z = iso.wall_matrix(layers_t, np.array(1j * omega))
        exact_out = np.array([-z[0, 0], 1]) / z[0, 1]
        exact_in = np.array([-1, z[1, 1]]) / z[0, 1]
        # The documented meaning of tolerance: error relative to the face's admittance.
        assert np.abs(got[0] - exact_out).max() <= tolerance * abs(exact_out[0])
        assert np.abs(got[1] - exact_in).max() <= tolerance * abs(exact_in[1])


def _discrete_flux_response(g: np.ndarray, cap: np.ndarray, omega: float) -> np.ndarray:
    """Surface fluxes of the semi-discrete model per unit surface temperature.

    Rows: outside, inside flux; columns: outside, inside temperature.
    """
    n = cap.size - 2
    bands = np.zeros((3, n), dtype=complex)
    bands[0, 1:] = bands[2, :-1] = -g[1:-1]
    bands[1] = g[:-1] + g[1:] + 1j * omega * cap[1:-1]
    rhs = np.zeros((n, 2), dtype=complex)
    rhs[0, 0], rhs[-1, 1] = g[0], g[-1]
    temp = solve_banded((1, 1), bands, rhs)
    flux_out = np.array([g[0] * (1 - temp[0, 0]) + 1j * omega * cap[0], -g[0] * temp[0, 1]])
    flux_in = np.array([g[-1] * temp[-1, 0], g[-1] * (temp[-1, 1] - 1) - 1j * omega * cap[-1]])
    return np.array([flux_out, flux_in])


# ---------------------------------------------------------------- step response

STEP_HOURS = np.array([1, 2, 4, 6, 8, 12, 24, 48, 72, 120])


def step_input(n: int) -> np.ndarray:
    """0 at the first sample, 1 after: a rise over the first clock step."""
    u = np.ones(n)
    u[0] = 0.0
    return u


@pytest.mark.parametrize("scheme", ["crank-nicolson", "backward-euler", "exact"])
def test_step_response_matches_talbot_inversion(scheme):
    wall = MultilayerWall(paper_layers(), scheme=scheme)
    n = 121 * 2
    q = wall.simulate({}, drive(SURFACE, step_input(n), np.zeros(n), HALF_HOUR))["heat_flux_in"]
    reference = [iso.ramp_transmittance(PAPER, h * HOUR, HALF_HOUR) for h in STEP_HOURS]
    # Requirement: within 1e-3 W/m² (per kelvin of step).
    np.testing.assert_allclose(q[STEP_HOURS * 2], reference, rtol=0, atol=1e-3)


def test_step_response_of_a_slab_matches_fourier_series():
    wall = MultilayerWall([Layer("concrete", *CB)], outputs=("heat_flux_in",))
    step = 600.0
    n = 24 * 6 + 1
    q = wall.simulate({}, drive(SURFACE, step_input(n), np.zeros(n), step))["heat_flux_in"]
    hours = np.array([1, 2, 6, 12, 24])
    reference = [iso.slab_step_flux(CB, h * HOUR, step) for h in hours]
    # Requirement: within 1e-3 W/m² (per kelvin of step).
    np.testing.assert_allclose(q[hours * 6], reference, rtol=0, atol=1e-3)


def test_crank_nicolson_does_not_ring_after_a_step():
    wall = MultilayerWall(paper_layers(), outputs=("heat_flux_out",))
    n = 97
    q = wall.simulate({}, drive(SURFACE, step_input(n), np.zeros(n), HALF_HOUR))["heat_flux_out"]
    # The exact outside flux decays monotonically once the rise is over; an
    # oscillating (ringing) scheme would make some differences positive.
    assert np.all(np.diff(q[1:]) < 0)


def test_spatial_convergence_is_second_order():
    hours = np.array([4, 8, 12, 24])
    reference = np.array([iso.ramp_transmittance(PAPER, h * HOUR, HALF_HOUR) for h in hours])
    n = 24 * 2 + 1
    errors = []
    for factor in (1, 2, 4):
        # Time-exact integration isolates the spatial error.
        wall = MultilayerWall(
            paper_layers(), scheme="exact", cells=(2 * factor, 4 * factor, 2 * factor)
        )
        q = wall.simulate({}, drive(SURFACE, step_input(n), np.zeros(n), HALF_HOUR))
        errors.append(np.abs(q["heat_flux_in"][hours * 2] - reference).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # Second-order scheme: observed orders approach 2 from the coarse side.
    assert np.all((orders > 1.8) & (orders < 2.2)), orders


def test_surface_fluxes_conserve_energy_between_steady_states():
    rng = np.random.default_rng(20240611)
    wall = MultilayerWall(paper_layers(), outputs=("heat_flux_out", "heat_flux_in"))
    start, end = rng.normal(size=(2, 2))
    n_random, n_hold = 48, 20 * 48
    outside = np.concatenate([start[:1], rng.normal(size=n_random), np.full(n_hold, end[0])])
    inside = np.concatenate([start[1:], rng.normal(size=n_random), np.full(n_hold, end[1])])
    out = wall.simulate({}, drive(SURFACE, outside, inside, HALF_HOUR))
    net = out["heat_flux_out"] - out["heat_flux_in"]
    gained = np.trapezoid(net, dx=HALF_HOUR)
    stored = _steady_energy(end) - _steady_energy(start)
    # Identity of the scheme (trapezoidal sum of the energy-consistent fluxes between
    # steady states): only round-off of ~1e4 J/m² sums remains. Leaving out the
    # half-cell storage would miss ~0.5 % of the stored energy here.
    assert gained == pytest.approx(stored, abs=1e-9 * np.abs(net).sum() * HALF_HOUR)


def _steady_energy(temps: np.ndarray) -> float:
    """Heat stored in the paper wall at steady state, relative to 0 °C. [J/m²]"""
    resist = np.concatenate([[0.0], np.cumsum([d / k for d, k, _, _ in PAPER])])
    t = temps[0] + (temps[1] - temps[0]) * resist / resist[-1]
    return sum(rho * c * d * (t[i] + t[i + 1]) / 2 for i, (d, _, rho, c) in enumerate(PAPER))


# ------------------------------------------------------------------ real wall


@pytest.mark.shared_data
def test_twin_house_west_wall_inside_flux():
    path = DATA / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"
    if not DATA.is_dir():
        pytest.skip(f"measured data folder {DATA} is absent (it sits beside the repository)")
    data = np.loadtxt(path, skiprows=2)
    names = ("ext_plaster", "eps", "old_plaster", "brick", "int_plaster")
    wall = MultilayerWall([Layer(name, *lt) for name, lt in zip(names, TWIN, strict=True)])
    step = float(data[1, 0] - data[0, 0])
    out = wall.simulate({}, drive(SURFACE, data[:, 18], data[:, 14], step))
    warm_up = int(3 * DAY / step)
    residual = out["heat_flux_in"][warm_up:] - data[warm_up:, 15]
    # Requirement from the issue (the measured flux has an SD of about 3.2 W/m²);
    # the nominal model gives about 0.46 W/m².
    assert np.sqrt(np.mean(residual**2)) < 0.6


# ------------------------------------------------------------ parameters, API


def test_parameters_map_onto_their_targets():
    wall = MultilayerWall(
        paper_layers(),
        parameters={
            "k_cb": ["concrete.conductivity"],
            "cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"],
            "d_cb": "concrete.thickness",
        },
    )
    assert wall.parameter_names == ("k_cb", "cp_fb", "d_cb")
    n = 3
    forcing = drive(SURFACE, np.zeros(n), np.full(n, 20.0), HALF_HOUR)
    for k_cb, d_cb in [(0.09, 0.15), (0.2, 0.1)]:
        q = wall.simulate({"k_cb": k_cb, "d_cb": d_cb}, forcing)["heat_flux_in"]
        u = u_value([GF, (d_cb, k_cb, 552.0, 800.0), GF])
        # Steady state is exact up to round-off.
        np.testing.assert_allclose(q, -20 * u, rtol=1e-10)


def test_shared_parameter_sets_every_target():
    n = 97
    forcing = drive(SURFACE, step_input(n), np.zeros(n), HALF_HOUR)
    calibrated = MultilayerWall(
        paper_layers(), parameters={"cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"]}
    ).simulate({"cp_fb": 1200.0}, forcing)["heat_flux_in"]
    changed = [
        Layer("fb_out", *GF[:3], 1200.0),
        Layer("concrete", *CB),
        Layer("fb_in", *GF[:3], 1200.0),
    ]
    direct = MultilayerWall(changed).simulate({}, forcing)["heat_flux_in"]
    nominal = MultilayerWall(paper_layers()).simulate({}, forcing)["heat_flux_in"]
    # Same wall built two ways: the same arithmetic, so identical to round-off.
    np.testing.assert_allclose(calibrated, direct, rtol=0, atol=1e-14)
    assert np.abs(calibrated - nominal).max() > 1e-3  # and the parameter matters


def test_wall_level_parameters():
    wall = MultilayerWall(
        paper_layers(),
        boundary="air",
        parameters={"rsi": "r_si", "alpha": "solar_absorptance"},
    )
    assert wall.input_names == ("temp_air_out", "temp_air_in", "poa_global_out")
    forcing = Forcing(
        HALF_HOUR,
        {
            "temp_air_out": np.zeros(2),
            "temp_air_in": np.full(2, 20.0),
            "poa_global_out": np.full(2, 300.0),
        },
    )
    q = wall.simulate({"rsi": 0.25, "alpha": 0.5}, forcing)["heat_flux_in"]
    u = u_value(PAPER, 0.25 + 0.04)
    np.testing.assert_allclose(q, -20 * u + 0.5 * 300 * 0.04 * u, rtol=1e-10)  # round-off


@pytest.mark.parametrize(
    ("parameters", "match"),
    [
        ({"k_unknown": 0.1}, "has no parameter"),
        ({"k_cb": 0.0}, "must be > 0"),
        ({"k_cb": -0.1}, "must be > 0"),
        ({"k_cb": float("nan")}, "not finite"),
    ],
)
def test_bad_parameter_values_raise(parameters, match):
    wall = MultilayerWall(paper_layers(), parameters={"k_cb": ["concrete.conductivity"]})
    forcing = drive(SURFACE, np.zeros(3), np.ones(3), HALF_HOUR)
    with pytest.raises(SimulatorError, match=match):
        wall.simulate(parameters, forcing)


def test_bad_absorptance_value_raises():
    wall = MultilayerWall(paper_layers(), boundary="air", parameters={"a": "solar_absorptance"})
    forcing = Forcing(
        HALF_HOUR,
        {"temp_air_out": np.zeros(2), "temp_air_in": np.zeros(2), "poa_global_out": np.zeros(2)},
    )
    with pytest.raises(SimulatorError, match=r"must be in \[0, 1\]"):
        wall.simulate({"a": 1.5}, forcing)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"parameters": {"k": ["brick.conductivity"]}}, "expected 'layer.property'"),
        ({"parameters": {"k": ["concrete.colour"]}}, "expected 'layer.property'"),
        ({"parameters": {"r": ["r_se"]}}, "no effect with boundary='surface'"),
        ({"solar_absorptance": 0.5}, "needs boundary='air'"),
        ({"boundary": "sky"}, "boundary must be one of"),
        ({"scheme": "euler"}, "scheme must be one of"),
        ({"tolerance": 0.0}, "tolerance must be in"),
        ({"outputs": ("heat_flux_interface_3",)}, "outputs must be distinct names"),
        ({"cells": (2, 2)}, "cells must give a positive count"),
        ({"boundary": "air", "r_si": -0.1}, "r_si must be > 0"),
    ],
)
def test_bad_construction_raises(kwargs, match):
    with pytest.raises(SimulatorError, match=match):
        MultilayerWall(paper_layers(), **kwargs)


def test_single_cell_with_imposed_surfaces_raises():
    with pytest.raises(SimulatorError, match="at least 2 cells in all"):
        MultilayerWall([Layer("concrete", *CB)], cells=(1,))


def test_duplicate_layer_names_raise():
    with pytest.raises(SimulatorError, match="layer names must be unique"):
        MultilayerWall([Layer("a", *GF), Layer("a", *CB)])


def test_missing_input_raises():
    wall = MultilayerWall(paper_layers(), boundary="air")
    with pytest.raises(SimulatorError, match="needs boundary condition"):
        wall.simulate({}, drive(SURFACE, np.zeros(3), np.zeros(3), HALF_HOUR))


def test_pickled_wall_gives_identical_output():
    wall = MultilayerWall(
        paper_layers(),
        parameters={"k_cb": ["concrete.conductivity"]},
        outputs=("heat_flux_in", "heat_flux_out", "temp_interface_2"),
    )
    assert isinstance(wall, Simulator)
    rng = np.random.default_rng(7)
    forcing = drive(SURFACE, rng.normal(size=200), rng.normal(size=200), HALF_HOUR)
    first = wall.simulate({"k_cb": 0.1}, forcing)
    again = pickle.loads(pickle.dumps(wall)).simulate({"k_cb": 0.1}, forcing)
    assert first.keys() == again.keys()
    for name in first:
        assert first[name].shape == (200,)
        np.testing.assert_array_equal(first[name], again[name])


def test_derived_quantities_of_the_paper_wall() -> None:
    # R = sum d/k, U with the surface resistances, kappa = sum rho c d (EN ISO 6946/13786).
    layers = [
        Layer("fb_out", 0.027, 0.0316, 116.6, 840.0),
        Layer("concrete", 0.150, 0.12, 552.0, 800.0),
        Layer("fb_in", 0.027, 0.0316, 116.6, 840.0),
    ]
    wall = MultilayerWall(layers, parameters={"k": "concrete.conductivity"}, r_si=0.13, r_se=0.04)
    got = wall.derived({"k": 0.15})
    r = 2 * 0.027 / 0.0316 + 0.150 / 0.15
    assert got["R_wall"] == pytest.approx(r, rel=1e-12)
    assert got["U_value"] == pytest.approx(1.0 / (r + 0.17), rel=1e-12)
    kappa = 2 * 116.6 * 840.0 * 0.027 + 552.0 * 800.0 * 0.150
    assert got["areal_heat_capacity"] == pytest.approx(kappa, rel=1e-12)
    assert set(wall.derived_units) == set(got)
    # The paper's wall at its nominal values: U of method.md section 8 (0.31961 W/(m²K)).
    nominal = MultilayerWall(layers, r_si=0.13, r_se=0.04).derived({})
    assert nominal["U_value"] == pytest.approx(0.31961, abs=5e-6)
