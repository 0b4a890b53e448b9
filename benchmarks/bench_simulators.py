"""Timings of the built-in simulators, measured in one run (median of repeats).

Run with ``OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/bench_simulators.py``
(the box part comes from ``bench_box.py`` beside it).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from bayescal.simulators.base import Forcing
from bayescal.simulators.fvm import Layer
from bayescal.simulators.wall import MultilayerWall, run_propagator


def _median_ms(run: Callable[[int], object], repeats: int) -> float:
    """Median wall-clock time of ``run(i)`` over ``repeats`` calls, after one warm-up. [ms]"""
    run(0)
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        run(i)
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def _surface_forcing(n: int, step: float, rng: np.random.Generator) -> Forcing:
    """Daily cycles plus noise on both surfaces. [°C]"""
    t = np.arange(n) * step
    daily = np.sin(2 * np.pi * t / 86400.0)
    return Forcing(
        step,
        {
            "temp_surf_out": 8 + 6 * daily + rng.normal(0, 0.5, n),
            "temp_surf_in": 22 + 0.5 * daily + rng.normal(0, 0.1, n),
        },
    )


def _time_wall(
    label: str, wall: MultilayerWall, sets: list[dict[str, float]], forcing: Forcing, repeats: int
) -> dict[str, float]:
    prop = wall.propagator(sets[0], forcing.step)
    inputs = np.column_stack([forcing[name] for name in wall.input_names])

    def full(i: int) -> object:
        return wall.simulate(sets[i], forcing)

    def setup(i: int) -> object:
        return wall.propagator(sets[i], forcing.step)

    def propagation(i: int) -> object:
        return run_propagator(prop, inputs, forcing.step)

    return {
        f"{label}_ms_per_run": _median_ms(full, repeats),
        f"{label}_setup_ms": _median_ms(setup, repeats),
        f"{label}_propagation_ms": _median_ms(propagation, repeats),
        f"{label}_nodes": float(prop.mesh.n_nodes),
        f"{label}_slow_modes": float(prop.rates.size),
    }


def bench_wall(repeats: int = 50, seed: int = 0) -> dict[str, float]:
    """Time the paper's wall (1500 half-hourly steps, imposed surface temperatures).

    Each timed run gets a new parameter set, as in a Latin-hypercube design, so
    the set-up (mesh, eigen-decomposition, step coefficients) is included.

    Returns
    -------
    dict
        ``wall_ms_per_run`` (set-up included), ``wall_setup_ms``,
        ``wall_propagation_ms`` (run with a precomputed propagator), the same
        with ``tolerance=1e-3`` and with Twin-House-like 5905 ten-minute steps,
        and mesh sizes. [ms or counts]
    """
    rng = np.random.default_rng(seed)
    layers = [
        Layer("fb_out", 0.027, 0.0316, 116.6, 840.0),
        Layer("concrete", 0.15, 0.12, 552.0, 800.0),
        Layer("fb_in", 0.027, 0.0316, 116.6, 840.0),
    ]
    mapping = {
        "k_cb": ["concrete.conductivity"],
        "cp_cb": ["concrete.specific_heat"],
        "cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"],
    }
    draws = rng.uniform([0.08, 600.0, 600.0], [0.16, 1200.0, 1200.0], size=(repeats + 1, 3))
    sets = [dict(zip(mapping, row, strict=True)) for row in draws]
    forcing = _surface_forcing(1500, 1800.0, rng)
    result: dict[str, float] = {}
    for label, tolerance in (("wall", 1e-2), ("wall_tol1e-3", 1e-3)):
        wall = MultilayerWall(layers, parameters=mapping, tolerance=tolerance)
        result |= _time_wall(label, wall, sets, forcing, repeats)
    long_forcing = _surface_forcing(5905, 600.0, rng)
    wall = MultilayerWall(layers, parameters=mapping)

    def long_run(i: int) -> object:
        return wall.simulate(sets[i], long_forcing)

    result["wall_5905x600s_ms_per_run"] = _median_ms(long_run, max(5, repeats // 5))
    return result


def main() -> None:
    """Print the timings of the wall and of the box, and their ratio to the targets."""
    from bench_box import bench_box

    wall = bench_wall()
    for name, value in wall.items():
        print(f"{name:32s} {value:10.3f}")
    print(
        f"wall: {wall['wall_ms_per_run']:.2f} ms per 1500-step run = "
        f"{wall['wall_ms_per_run'] / 50.0:.3f} of the 50 ms target"
    )
    box = bench_box()
    for name, value in box.items():
        print(f"box {name:28s} {value:10.3f} s")
    print(
        f"box: {box['coheating']:.2f} s per 4-week 5-minute run = "
        f"{box['coheating'] / 2.0:.3f} of the 2 s target"
    )


if __name__ == "__main__":
    main()
