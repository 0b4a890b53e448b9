"""The chains' diagnostics: one ArviZ call per statistic against one per statistic and parameter.

:func:`bayescal.mcmc.diagnostics.diagnose` (R-hat, bulk and tail ESS, MCSE of the
mean and SD) runs after every calibration and each of its extensions, and again
whenever a posterior is read back. Until 2026-11-30 it called each ArviZ
statistic once per parameter, each call computing it for every parameter: the
work grew with the square of the coordinates. For chains of the sizes the
examples keep, in one process with single-threaded BLAS, this prints the seconds
of the present code (one call per statistic) and of that former loop (written
out below), and their ratio; the values are checked equal.

Run::

    .venv/bin/python benchmarks/bench_diagnostics.py
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import time  # noqa: E402

import arviz as az  # noqa: E402
import numpy as np  # noqa: E402

from bayescal.mcmc.diagnostics import STATISTICS, _arviz_values, to_inference_data  # noqa: E402

#: (chains, kept draws, coordinates); the second is the Twin House at its cap.
SIZES = ((4, 1000, 4), (4, 3200, 9), (4, 2400, 18))


def per_parameter(draws: np.ndarray, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The former loop: every statistic computed for all parameters once per parameter."""
    idata = to_inference_data(draws, names)
    out = {}
    for key, (function, method) in STATISTICS.items():
        call = getattr(az, function)
        out[key] = np.array([float(call(idata, method=method)[n]) for n in names])
    return out


def main() -> None:
    rng = np.random.default_rng(7)
    print("chains x draws x coordinates | one call per statistic [s] | per parameter [s] | ratio")
    for chains, n, d in SIZES:
        draws = rng.standard_normal((chains, n, d)).cumsum(axis=1) * 0.02
        draws += rng.standard_normal((chains, n, d))
        names = tuple(f"x{k}" for k in range(d))
        _arviz_values(draws, names)  # imports and caches warmed
        start = time.perf_counter()
        new = _arviz_values(draws, names)
        t_new = time.perf_counter() - start
        start = time.perf_counter()
        old = per_parameter(draws, names)
        t_old = time.perf_counter() - start
        for key in old:
            np.testing.assert_allclose(new[key], old[key], rtol=1e-12)
        print(f"{chains} x {n} x {d} | {t_new:.3f} | {t_old:.3f} | {t_old / t_new:.1f}")


if __name__ == "__main__":
    main()
