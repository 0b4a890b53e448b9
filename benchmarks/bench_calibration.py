"""Calibration stage on the virtual wall: log-density cost, MCMC speed and ESS per second.

For the paper's size (R = 30 runs x m* = 25 daily periods) and for R = 200 x
m* = 100, on the virtual wall of ``tests/helpers/virtual_wall.py`` (basis at 99 % of
the variance), prints

* the emulator training time (MwG over eq. 9, one chain) and its cost per sweep;
* ms per calibration log-density evaluation (eq. 16, theta* moving) for the
  Kronecker and the dense back ends, measured in this process, and their ratio
  (the dense one at the large size from ``--large-dense-evals`` evaluations);
* seconds per 1000 MwG sweeps (each sweep updates theta*, lambda and lambda*
  once) and the bulk ESS per second of theta* (the smallest over parameters),
  4 chains run serially so the seconds are single-core seconds.

BLAS is single-threaded (set before numpy is imported)::

    .venv/bin/python benchmarks/bench_calibration.py
    .venv/bin/python benchmarks/bench_calibration.py --large-dense-evals 0   # skip dense at 200x100
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from bayescal.calibration.kron import Kind, make_algebra  # noqa: E402
from bayescal.calibration.posterior import calibrate  # noqa: E402
from bayescal.calibration.target import CalibrationPosterior  # noqa: E402
from bayescal.emulator.assemble import Assembled, assemble  # noqa: E402
from bayescal.emulator.gp import Emulator  # noqa: E402
from bayescal.emulator.training import train  # noqa: E402
from virtual_wall import virtual_experiment  # noqa: E402


def _target(kind: Kind, em: Emulator, a: Assembled) -> CalibrationPosterior:
    alg = make_algebra(kind, em.theta, em.x, em.kernels, em.basis.ktk, em.w, a.w_star)
    return CalibrationPosterior(alg, list(a.priors.values()), em.lam_prior, a.lam_star_prior)


def _ms_per_eval(target: CalibrationPosterior, points: np.ndarray) -> float:
    start = time.perf_counter()
    for v in points:
        target(v)
    return 1e3 * (time.perf_counter() - start) / len(points)


def run_case(runs: int, periods: int, train_sweeps: tuple[int, int], dense_evals: int) -> None:
    """Build, train, time the log-densities and the MCMC for one problem size."""
    print(f"\n=== R = {runs} runs x m* = {periods} periods ===")
    start = time.perf_counter()
    ve = virtual_experiment(seed=0, runs=runs, periods=periods)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, variance=0.99)
    print(
        f"  simulate + assemble: {time.perf_counter() - start:.2f} s; p = {a.basis.p}, "
        f"s = {a.x.shape[1]}, N = {a.n_runs * a.n_periods + a.n_periods} rows per basis"
    )
    n_burn, n_draws = train_sweeps
    start = time.perf_counter()
    em = train(a, n_burn=n_burn, n_draws=n_draws, n_chains=1, seed=1, refine=runs <= 50)
    took = time.perf_counter() - start
    print(
        f"  emulator training ({n_burn + n_draws} sweeps of {em.layout.d} coordinates): "
        f"{took:.1f} s = {1e3 * took / (n_burn + n_draws):.1f} ms per sweep"
    )

    rng = np.random.default_rng(0)
    points = np.column_stack(
        [
            rng.random((200, 3)),
            np.full(200, em.lam),
            np.full(200, a.lam_star_prior[0] / a.lam_star_prior[1]),
        ]
    )
    kron = _target("kronecker", em, a)
    t_kron = _ms_per_eval(kron, points)
    print(f"  Kronecker log-density: {t_kron:.3f} ms per evaluation")
    if dense_evals > 0:
        dense = _target("dense", em, a)
        t_dense = _ms_per_eval(dense, points[:dense_evals])
        diff = abs(dense(points[0]) - kron(points[0]))
        print(
            f"  dense log-density ({dense_evals} evals): {t_dense:.1f} ms per evaluation; "
            f"dense / Kronecker = {t_dense / t_kron:.0f}; |difference| = {diff:.2e}"
        )
    else:
        print("  dense log-density: not measured")

    n_burn_c, n_draws_c = 500, 1000
    start = time.perf_counter()
    post = calibrate(
        em, a, n_chains=4, n_burn=n_burn_c, n_draws=n_draws_c, seed=3, backend="serial"
    )
    took = time.perf_counter() - start
    sweeps = 4 * (n_burn_c + n_draws_c)
    ess = post.diagnostics.ess_bulk[:3]
    print(
        f"  calibration MCMC (4 chains x {n_burn_c + n_draws_c} sweeps, serial): {took:.1f} s "
        f"= {1e3 * took / sweeps:.2f} s per 1000 sweeps"
    )
    print(
        "  bulk ESS of theta*: "
        + ", ".join(f"{n} {e:.0f}" for n, e in zip(post.names, ess, strict=True))
    )
    print(
        f"  ESS per second (smallest over theta*): {ess.min() / took:.0f} /s; "
        f"warnings: {len(post.warnings)}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--small-dense-evals", type=int, default=20)
    parser.add_argument("--large-dense-evals", type=int, default=1)
    opts = parser.parse_args()
    run_case(30, 25, (400, 100), opts.small_dense_evals)
    run_case(200, 100, (20, 5), opts.large_dense_evals)


if __name__ == "__main__":
    main()
