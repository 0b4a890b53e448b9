"""Time the test box simulator over the paper's record length: 4 weeks at 5 minutes.

Synthetic but realistic weather for Uccle (50.8°N, 4.35°E) in March: clear-sky
global and diffuse irradiance (pvlib, Ineichen–Perez), a daily outside
temperature cycle, a varying wind and relative humidity (so the Berdahl–Martin
sky model is used). Both modes are timed; the solar geometry and transposition
are included in each run, as in a calibration design.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_box.py``.
"""

from __future__ import annotations

import time

import numpy as np

from bayescal.simulators import solar
from bayescal.simulators.base import Forcing
from bayescal.simulators.box import TestBox

LATITUDE, LONGITUDE = 50.8, 4.35


def weather(n: int = 8064, step: float = 300.0) -> dict[str, np.ndarray]:
    """Four weeks of synthetic weather from 1 March 2013, UTC."""
    start = np.datetime64("2013-03-01T00:00", "s")
    times = start + (np.arange(n) * step).astype("timedelta64[s]")
    ghi, dhi = solar.clear_sky(times, LATITUDE, LONGITUDE)
    hours = np.arange(n) * step / 3600.0
    return {
        "temp_air_out": 6.0 + 5.0 * np.sin(2 * np.pi * (hours - 9.0) / 24.0),
        "ghi": ghi,
        "dhi": dhi,
        "wind_speed": 2.5 + 2.0 * np.sin(2 * np.pi * hours / 53.0) ** 2,
        "relative_humidity": 75.0 + 15.0 * np.cos(2 * np.pi * hours / 24.0),
    }


def bench_box(repeats: int = 3) -> dict[str, float]:
    """Wall-clock seconds per 4-week, 5-minute run (best of ``repeats``) for each mode.

    Also reports the process CPU time of the same run as ``"<mode> cpu"``, which
    is less sensitive to other work on a shared machine.
    """
    n, step = 8064, 300.0
    series = weather(n, step)
    start = np.datetime64("2013-03-01T00:00")
    forcings = {
        "coheating": Forcing(step, {**series, "temp_air_in": np.full(n, 25.0)}, start),
        "freefloat": Forcing(step, {**series, "heat_input": np.zeros(n)}, start),
    }
    seconds = {}
    for mode, forcing in forcings.items():
        box = TestBox(mode=mode, latitude=LATITUDE, longitude=LONGITUDE)
        wall, cpu = [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            box.simulate({"k_wall": 0.126, "d_wall": 1937.0}, forcing)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        seconds[mode] = min(wall)
        seconds[f"{mode} cpu"] = min(cpu)
    return seconds


if __name__ == "__main__":
    for name, s in bench_box().items():
        print(f"test box, {name}, 8064 steps of 5 min: {s:.3f} s per run")
