"""A calibration density on random data, for tests of the calibration's algebra and targets."""

from __future__ import annotations

import numpy as np

from bayescal.calibration.kron import KronCalibrationDensity
from bayescal.emulator.kernel import SeparableKernel


def random_density(seed: int = 0, runs: int = 12, periods: int = 8) -> KronCalibrationDensity:
    """A calibration density on random data: t = 3, s = 2, p = 2 bases."""
    rng = np.random.default_rng(seed)
    t, s, p = 3, 2, 2
    kernels = [
        SeparableKernel(rng.uniform(0.3, 0.9, t + s), float(rng.uniform(0.5, 2.0)), t)
        for _ in range(p)
    ]
    w = rng.standard_normal((runs * periods, p))
    w_star = rng.standard_normal((periods, p))
    return KronCalibrationDensity(
        rng.random((runs, t)), rng.random((periods, s)), kernels, [2.0, 0.5], w, w_star
    )
