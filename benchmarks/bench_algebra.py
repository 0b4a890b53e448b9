"""Calibration log-density: dense Cholesky versus the Kronecker fast path.

Prints, for the paper's wall (R = 30 runs, m* = 25 periods, t = 3, s = 4, p = 2)
and for R = 200 x m* = 100, the milliseconds per calibration log-density
evaluation of both back ends measured in this process, their ratio, the
agreement of the two, and the time of the two small eigen-decompositions
(``S_theta`` R x R and ``S_x`` m* x m*) that any Kronecker method needs.

BLAS runs single-threaded unless ``BAYESCAL_BENCH_THREADS`` says otherwise
(set before numpy is imported, so it must be in the environment)::

    .venv/bin/python benchmarks/bench_algebra.py
    BAYESCAL_BENCH_THREADS=2 .venv/bin/python benchmarks/bench_algebra.py --skip-large-dense

The dense evaluation at the large size (N = 20 100 rows, ~3 GB per matrix)
takes minutes; it is timed once per basis (``--large-dense-evals``) or skipped.
"""

from __future__ import annotations

import os

_THREADS = os.environ.get("BAYESCAL_BENCH_THREADS", "1")
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = _THREADS

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402

from bayescal.calibration.dense import DenseCalibrationDensity  # noqa: E402
from bayescal.calibration.kron import KronCalibrationDensity  # noqa: E402
from bayescal.emulator.kernel import SeparableKernel  # noqa: E402


@dataclass(frozen=True)
class Case:
    name: str
    n_runs: int
    n_periods: int
    n_theta: int = 3
    n_x: int = 4
    n_bases: int = 2


Args = tuple[np.ndarray, np.ndarray, list[SeparableKernel], np.ndarray, np.ndarray, np.ndarray]


def _problem(case: Case, rng: np.random.Generator) -> Args:
    """A synthetic problem shaped like a real one (values do not matter for timing)."""
    r = case.n_theta + case.n_x
    kernels = [
        SeparableKernel(rng.uniform(0.2, 0.95, r), rng.uniform(0.5, 2.0), case.n_theta)
        for _ in range(case.n_bases)
    ]
    return (
        rng.random((case.n_runs, case.n_theta)),
        rng.random((case.n_periods, case.n_x)),
        kernels,
        np.linspace(30.0, 5.0, case.n_bases),
        rng.normal(size=(case.n_runs * case.n_periods, case.n_bases)),
        rng.normal(size=(case.n_periods, case.n_bases)),
    )


def _per_call(fn: Callable[[int], object], n_calls: int, repeats: int = 7) -> float:
    """Seconds per call: the best of ``repeats`` batches (robust to a busy machine)."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for i in range(n_calls):
            fn(i)
        best = min(best, (time.perf_counter() - start) / n_calls)
    return best


def _time_dense_once(
    dense: DenseCalibrationDensity, theta_star: np.ndarray
) -> tuple[float, float, float]:
    """Wall seconds, CPU seconds of this process, and the log-density."""
    start, cpu = time.perf_counter(), time.process_time()
    value = dense.logpdf(theta_star, 1e3, 50.0)
    return time.perf_counter() - start, time.process_time() - cpu, value


def run_case(case: Case, rng: np.random.Generator, dense_evals: int) -> None:
    args = _problem(case, rng)
    theta_stars = rng.random((64, case.n_theta))
    lam, lam_star = 1e3, 50.0
    n_rows = case.n_runs * case.n_periods + case.n_periods
    print(
        f"\n== {case.name}: R={case.n_runs}, m*={case.n_periods}, t={case.n_theta}, "
        f"s={case.n_x}, p={case.n_bases}  (N = {n_rows} rows per basis)"
    )

    start = time.perf_counter()
    fast = KronCalibrationDensity(*args)
    setup = time.perf_counter() - start
    eigen = KronCalibrationDensity(*args, method="eigen")
    n_fast = 500
    t_fast = _per_call(lambda i: fast.logpdf(theta_stars[i % 64], lam, lam_star), n_fast)
    t_fast_lam = _per_call(
        lambda i: fast.logpdf(theta_stars[i % 64], lam * (1.0 + 1e-9 * i), lam_star), n_fast
    )
    t_eig = _per_call(lambda i: eigen.logpdf(theta_stars[i % 64], lam, lam_star), n_fast // 10)
    kern = args[2][0]
    s_theta, s_x = kern.theta_cov(args[0]), kern.x_corr(args[1])
    t_eig_theta = _per_call(lambda i: linalg.eigh(s_theta), 20)
    t_eig_x = _per_call(lambda i: linalg.eigh(s_x), 20)

    print(f"  kronecker setup (once per calibration):      {1e3 * setup:10.3f} ms")
    print(f"  kronecker 'schur' (default), theta* moving:  {1e3 * t_fast:10.4f} ms")
    print(f"  kronecker 'schur', lambda moving every call: {1e3 * t_fast_lam:10.4f} ms")
    print(f"  kronecker 'eigen' (method.md), per eval.:    {1e3 * t_eig:10.4f} ms")
    print(
        f"  eigh S_theta ({case.n_runs}x{case.n_runs}), one basis:          "
        f"{1e3 * t_eig_theta:10.4f} ms"
    )
    print(
        f"  eigh S_x ({case.n_periods}x{case.n_periods}), one basis:              "
        f"{1e3 * t_eig_x:10.4f} ms"
    )

    if dense_evals <= 0:
        print("  dense: not measured (--skip-large-dense)")
        return
    dense = DenseCalibrationDensity(*args)
    times, cpu_times, worst = [], [], 0.0
    for k in range(dense_evals):
        ts = theta_stars[k]
        elapsed, cpu, value = _time_dense_once(dense, ts)
        times.append(elapsed)
        cpu_times.append(cpu)
        ref = fast.pieces(ts, lam, lam_star)
        worst = max(worst, abs(ref.logpdf - value) / abs(value))
        worst = max(worst, abs(eigen.logpdf(ts, lam, lam_star) - value) / abs(value))
    t_dense = float(np.median(times))
    print(f"  dense Cholesky, per evaluation ({dense_evals} evals): {1e3 * t_dense:10.1f} ms")
    print(
        f"    (CPU time of this process: {1e3 * float(np.median(cpu_times)):.1f} ms; "
        "much less than wall time means a busy machine)"
    )
    print(f"  ratio dense / kronecker 'schur':             {t_dense / t_fast:10.0f}x")
    print(f"  ratio dense / kronecker 'eigen':             {t_dense / t_eig:10.0f}x")
    print(f"  max relative difference of logpdf vs dense:  {worst:10.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=20240601)
    parser.add_argument("--small-dense-evals", type=int, default=20)
    parser.add_argument("--large-dense-evals", type=int, default=1)
    parser.add_argument("--skip-large-dense", action="store_true")
    opts = parser.parse_args()
    rng = np.random.default_rng(opts.seed)
    print(f"BLAS threads: {_THREADS}; numpy {np.__version__}")
    run_case(Case("paper's wall", 30, 25), rng, opts.small_dense_evals)
    large = 0 if opts.skip_large_dense else opts.large_dense_evals
    run_case(Case("large", 200, 100), rng, large)


if __name__ == "__main__":
    main()
