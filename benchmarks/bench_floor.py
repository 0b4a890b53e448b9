"""Log-density cost against the floor of its unavoidable linear algebra (issue 7).

For each problem size, in one process with single-threaded BLAS, prints per
kind of Metropolis-within-Gibbs move

* **eval**: CPU milliseconds per call of the real target
  (:class:`~bayescal.calibration.posterior.CalibrationPosterior` with the
  Kronecker back end, or :class:`~bayescal.emulator.gp.TrainingPosterior`),
  each call moving one coordinate to a value not seen before;
* **floor**: milliseconds of the operations no exact method can skip for that
  move, written as bare numpy/scipy calls on arrays prepared beforehand (no
  validation, no caching logic, no Python objects);
* **ratio** eval / floor (issue target: under 3).

Floors. Calibration, ``theta*`` moving (per basis): the kernel vector
``c = S_theta(theta, theta*)``, its rotation ``Q_t^T c`` and the two
``R x m*`` contractions giving the Schur complement (nothing is decomposed;
``S_x``'s eigen-decomposition and the rotated weights ``Q_t^T W Q_x`` never
move). ``lambda`` moving: the ``R x m*`` eigenvalue grid, its logarithm and
the re-weighted rotated weights, then the same contractions (``Q_t^T c`` is
kept). ``lambda*`` moving: the ``m*`` Schur diagonal only. For scale, the
``(R+1)``-row eigen-decomposition of method.md's construction is printed too.
Training, one basis's ``theta`` correlation parameter moving: building
``R_theta`` (``R x R`` exponentials), its eigen-decomposition and the rotation
``Q_t^T (W Q_x)`` with ``W Q_x`` kept; an ``x`` parameter: the same with
``R_x`` (``m* x m*``) and ``(Q_t^T W) Q_x``; ``tau`` of one basis and
``lambda`` (all bases): the ``R x m*`` eigenvalue grid, its logarithm and the
quadratic form.

Also checked (by counting eigen-decompositions during the timed calls): a
calibration evaluation decomposes nothing, and a training evaluation
decomposes only the one factor of the one basis whose parameter moved.
``--profile`` profiles (cProfile) one calibration MCMC run and one emulator
training on the virtual wall at the paper's size and prints what dominates.

Run (BLAS threads are set to 1 before numpy is imported)::

    .venv/bin/python benchmarks/bench_floor.py                  # 30x25, 200x100, 500x200
    .venv/bin/python benchmarks/bench_floor.py --quick          # 30x25 only
    .venv/bin/python benchmarks/bench_floor.py --profile        # + cProfile of the MCMC
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import contextlib  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import pstats  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterator  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402

from bayescal.calibration.kron import KronCalibrationDensity  # noqa: E402
from bayescal.calibration.target import CalibrationPosterior  # noqa: E402
from bayescal.design import UniformPrior  # noqa: E402
from bayescal.emulator import kron  # noqa: E402
from bayescal.emulator.kernel import SeparableKernel  # noqa: E402
from bayescal.emulator.training import TrainingPosterior  # noqa: E402

LAM, LAM_STAR = 1e3, 50.0


@dataclass(frozen=True)
class Case:
    """Problem size: runs, periods, calibration and condition inputs, bases."""

    name: str
    n_runs: int
    n_periods: int
    n_theta: int = 3
    n_x: int = 4
    n_bases: int = 2


CASES = (
    Case("paper's wall", 30, 25),
    Case("medium", 200, 100),
    Case("scale target", 500, 200, n_bases=5),
)


@dataclass(frozen=True)
class Problem:
    """A synthetic problem shaped like a real one (values do not matter for timing)."""

    theta: np.ndarray
    x: np.ndarray
    kernels: list[SeparableKernel]
    ktk: np.ndarray
    w: np.ndarray
    w_star: np.ndarray

    @classmethod
    def draw(cls, case: Case, rng: np.random.Generator) -> Problem:
        r = case.n_theta + case.n_x
        kernels = [
            SeparableKernel(rng.uniform(0.2, 0.95, r), rng.uniform(0.5, 2.0), case.n_theta)
            for _ in range(case.n_bases)
        ]
        return cls(
            rng.random((case.n_runs, case.n_theta)),
            rng.random((case.n_periods, case.n_x)),
            kernels,
            np.linspace(30.0, 5.0, case.n_bases),
            rng.normal(size=(case.n_runs * case.n_periods, case.n_bases)),
            rng.normal(size=(case.n_periods, case.n_bases)),
        )

    def grid(self, j: int) -> np.ndarray:
        """Weights of basis ``j`` as ``(R, m*)``."""
        return self.w[:, j].reshape(self.theta.shape[0], self.x.shape[0])


class EigCounter:
    """Counts :meth:`SymEig.of` calls (every eigen-decomposition of the package)."""

    def __init__(self) -> None:
        self.n = 0

    @contextlib.contextmanager
    def counting(self) -> Iterator[EigCounter]:
        original = kron.SymEig.__dict__["of"]

        def of(cls: type[kron.SymEig], matrix: np.ndarray) -> kron.SymEig:
            self.n += 1
            return original.__func__(cls, matrix)

        kron.SymEig.of = classmethod(of)  # type: ignore[assignment, method-assign]
        try:
            yield self
        finally:
            kron.SymEig.of = original  # type: ignore[method-assign]


def per_call(fn: Callable[[int], object], n_calls: int, repeats: int = 5) -> float:
    """CPU seconds of this process per call, the best of ``repeats`` batches.

    CPU time, not wall time: everything here is single-threaded, so on an idle
    machine the two agree, and on a shared one CPU time is not inflated by
    waiting for a core (the machine these numbers come from has 2 cores and
    other jobs).
    """
    best = np.inf
    offset = 0
    for _ in range(repeats):
        start = time.process_time()
        for i in range(offset, offset + n_calls):
            fn(i)
        best = min(best, (time.process_time() - start) / n_calls)
        offset += n_calls
    return best


def n_calls_for(case: Case, base: int) -> int:
    """Fewer calls for larger problems (a few seconds per measurement)."""
    return max(10, base * 30 * 25 // (case.n_runs * case.n_periods))


def show(label: str, t_eval: float, t_floor: float, n_eig: str) -> None:
    print(
        f"  {label:<34s} eval {1e3 * t_eval:9.4f} ms  floor {1e3 * t_floor:9.4f} ms  "
        f"ratio {t_eval / t_floor:5.2f}  {n_eig}"
    )


# --------------------------------------------------------------------------- calibration


@dataclass(frozen=True)
class CalFloor:
    """Bare arrays of one basis for the calibration floor."""

    variance: float
    beta_t: np.ndarray
    q_t: np.ndarray
    l_x: np.ndarray
    w_rot: np.ndarray
    obs_rot: np.ndarray

    @classmethod
    def build(cls, pb: Problem, j: int) -> CalFloor:
        kern = pb.kernels[j]
        qt = linalg.eigh(kern.theta_cov(pb.theta))[1]
        lx, qx = linalg.eigh(kern.x_corr(pb.x))
        return cls(
            kern.variance, kern.beta_theta, qt, lx, qt.T @ pb.grid(j) @ qx, qx.T @ pb.w_star[:, j]
        )


def _sim_pieces(
    lt: np.ndarray, f: CalFloor, a: float
) -> tuple[float, float, np.ndarray, np.ndarray]:
    den = np.multiply.outer(lt, f.l_x) + a
    logdet = float(np.sum(np.log(den)))
    inv_den = 1.0 / den
    h = f.w_rot * inv_den
    return logdet, float(np.vdot(h, f.w_rot)), inv_den, h


def _schur(
    f: CalFloor, c_hat: np.ndarray, h: np.ndarray, inv_den: np.ndarray, a_star: float
) -> float:
    u = f.l_x * (c_hat @ h)
    g = f.l_x * f.l_x * ((c_hat * c_hat) @ inv_den)
    schur = f.variance * f.l_x + a_star - g
    resid = f.obs_rot - u
    return float(np.sum(np.log(schur))) + float(np.vdot(resid, resid / schur))


def calibration(case: Case, pb: Problem, rng: np.random.Generator) -> tuple[float, float]:
    """Eval and floor per move kind; returns the per-sweep totals (eval, floor)."""
    counter = EigCounter()
    with counter.counting():
        dens = KronCalibrationDensity(pb.theta, pb.x, pb.kernels, pb.ktk, pb.w, pb.w_star)
    n_setup = counter.n
    t = case.n_theta
    target = CalibrationPosterior(dens, [UniformPrior(0.0, 1.0)] * t, (5.0, 5e-3), (5.0, 0.1))
    floors = [CalFloor.build(pb, j) for j in range(case.n_bases)]
    lts = [linalg.eigh(k.theta_cov(pb.theta), eigvals_only=True) for k in pb.kernels]
    a = 1.0 / (LAM * pb.ktk)
    a_star = 1.0 / (LAM_STAR * pb.ktk)
    n = n_calls_for(case, 400)
    ts = rng.uniform(0.05, 0.95, (6 * n, t))

    def point(i: int, lam: float = LAM, lam_star: float = LAM_STAR) -> np.ndarray:
        return np.concatenate([ts[i], [lam, lam_star]])

    sims = [_sim_pieces(lts[j], f, a[j]) for j, f in enumerate(floors)]
    target(point(0))
    counter.n = 0
    with counter.counting():
        t_theta = per_call(lambda i: target(point(i)), n)
        t_lam = per_call(lambda i: target(point(0, LAM * (1.0 + 1e-6 * (i + 1)))), n)
        t_lam_s = per_call(lambda i: target(point(0, LAM, LAM_STAR * (1.0 + 1e-6 * i))), n)
    n_eval_eig = counter.n

    def c_hat(f: CalFloor, i: int) -> np.ndarray:
        diff = pb.theta - ts[i]
        return f.q_t.T @ (f.variance * np.exp(-((diff * diff) @ f.beta_t)))

    def floor_theta(i: int) -> None:
        for j, f in enumerate(floors):
            _schur(f, c_hat(f, i), sims[j][3], sims[j][2], a_star[j])

    c_hats = [c_hat(f, 0) for f in floors]

    def floor_lam(i: int) -> None:
        for j, f in enumerate(floors):
            _, _, inv_den, h = _sim_pieces(lts[j], f, a[j] * (1.0 + 1e-6 * i))
            _schur(f, c_hats[j], h, inv_den, a_star[j])

    kept = []  # u and g from the last theta* or lambda move, per basis
    for j, f in enumerate(floors):
        g = f.l_x * f.l_x * ((c_hats[j] * c_hats[j]) @ sims[j][2])
        kept.append((f.obs_rot - f.l_x * (c_hats[j] @ sims[j][3]), f.variance * f.l_x - g))

    def floor_lam_star(i: int) -> None:
        for j, (resid, base) in enumerate(kept):
            schur = base + a_star[j] * (1.0 + 1e-6 * i)
            float(np.sum(np.log(schur))) + float(np.vdot(resid, resid / schur))

    f_theta = per_call(floor_theta, n)
    f_lam = per_call(floor_lam, n)
    f_lam_s = per_call(floor_lam_star, n)

    n1 = case.n_runs + 1
    m_eig = rng.random((n1, n1))
    m_eig = m_eig @ m_eig.T
    v_x = rng.random((n1, case.n_periods))
    t_eigen = per_call(lambda i: linalg.eigh(m_eig, check_finite=False, driver="evd"), 5, 3)
    t_rot = per_call(lambda i: m_eig.T @ v_x, 5, 3)

    print(
        f"  calibration (Kronecker 'schur'; {n_setup} eigen-decompositions at set-up, "
        f"{n_eval_eig} during {15 * n} timed evaluations)"
    )
    show("theta* moving", t_theta, f_theta, "")
    show("lambda moving (all bases)", t_lam, f_lam, "")
    show("lambda* moving", t_lam_s, f_lam_s, "")
    eigen_floor = case.n_bases * (t_eigen + t_rot)
    print(
        f"  for scale: method.md's (R+1) eigen-decomposition + rotation, all bases: "
        f"{1e3 * eigen_floor:.3f} ms per theta* move"
    )
    sweep_eval = t * t_theta + t_lam + t_lam_s
    sweep_floor = t * f_theta + f_lam + f_lam_s
    print(
        f"  per sweep ({t} x theta*, lambda, lambda*): eval {1e3 * sweep_eval:.3f} ms, "
        f"floor {1e3 * sweep_floor:.3f} ms, ratio {sweep_eval / sweep_floor:.2f}"
    )
    if n_eval_eig:
        print("  CHECK FAILED: a calibration evaluation decomposed a matrix")
    return sweep_eval, sweep_floor


# --------------------------------------------------------------------------- training


def training(case: Case, pb: Problem, rng: np.random.Generator) -> tuple[float, float]:
    """Eval and floor per move kind; returns the per-sweep totals (eval, floor)."""
    target = TrainingPosterior(pb.theta, pb.x, pb.w, pb.ktk, (5.0, 5e-3))
    layout = target.layout
    beta = np.array([k.beta for k in pb.kernels])
    tau = np.array([k.tau for k in pb.kernels])
    v0 = layout.pack(beta, tau, LAM)
    t = case.n_theta
    i_bt, i_bx, i_tau, i_lam = 0, t, layout.r, layout.lam_index
    n = n_calls_for(case, 200)
    jitter = rng.uniform(0.5, 1.5, 6 * n)

    def moved(index: int) -> Callable[[int], float]:
        def call(i: int) -> float:
            v = v0.copy()
            v[index] *= jitter[i]
            return target(v)

        return call

    target(v0)
    counter = EigCounter()
    timings, counts = {}, {}
    for label, index in (("bt", i_bt), ("bx", i_bx), ("tau", i_tau), ("lam", i_lam)):
        target(v0)  # the unmoved factors back in the memo
        counter.n = 0
        with counter.counting():
            timings[label] = per_call(moved(index), n)
        counts[label] = counter.n / (5 * n)

    kern = pb.kernels[0]
    w0 = pb.grid(0)
    lx, qx = linalg.eigh(kern.x_corr(pb.x))
    lt, qt = linalg.eigh(kern.theta_cov(pb.theta) / kern.variance)
    w_qx, qt_w = w0 @ qx, qt.T @ w0
    d_t, d_x = target.d_theta, target.d_x
    b_t, b_x = kern.beta_theta, kern.beta_x

    def finish(lt_: np.ndarray, lx_: np.ndarray, rot: np.ndarray, a: float) -> float:
        den = np.multiply.outer(lt_ / kern.tau, lx_) + a
        return float(np.sum(np.log(den))) + float(np.sum(rot * rot / den))

    a0 = 1.0 / (LAM * pb.ktk[0])

    def floor_bt(i: int) -> None:
        bt = b_t.copy()
        bt[0] *= jitter[i]
        corr = np.exp(-np.tensordot(bt, d_t, axes=1))
        l_new, q_new = linalg.eigh(corr, check_finite=False, driver="evd")
        finish(l_new, lx, q_new.T @ w_qx, a0)

    def floor_bx(i: int) -> None:
        bx = b_x.copy()
        bx[0] *= jitter[i]
        corr = np.exp(-np.tensordot(bx, d_x, axes=1))
        l_new, q_new = linalg.eigh(corr, check_finite=False, driver="evd")
        finish(lt, l_new, qt_w @ q_new, a0)

    rot0 = qt.T @ w0 @ qx

    def floor_tau(i: int) -> None:
        finish(lt * jitter[i], lx, rot0, a0)

    def floor_lam(i: int) -> None:
        for _ in range(case.n_bases):
            finish(lt, lx, rot0, a0 * jitter[i])

    floors = {
        "bt": per_call(floor_bt, n),
        "bx": per_call(floor_bx, n),
        "tau": per_call(floor_tau, n),
        "lam": per_call(floor_lam, n),
    }
    print("  training (one coordinate moving; eigen-decompositions per evaluation)")
    labels = {
        "bt": "theta corr. parameter of 1 basis",
        "bx": "x corr. parameter of 1 basis",
        "tau": "tau of 1 basis",
        "lam": "lambda (all bases)",
    }
    for key, label in labels.items():
        show(label, timings[key], floors[key], f"eigh/eval {counts[key]:.2f}")
    p, s = case.n_bases, case.n_x
    weights = {"bt": t * p, "bx": s * p, "tau": p, "lam": 1}
    sweep_eval = sum(weights[k] * timings[k] for k in weights)
    sweep_floor = sum(weights[k] * floors[k] for k in weights)
    print(
        f"  per sweep ({layout.d} coordinates): eval {1e3 * sweep_eval:.2f} ms, "
        f"floor {1e3 * sweep_floor:.2f} ms, ratio {sweep_eval / sweep_floor:.2f}"
    )
    expected = {"bt": 1.0, "bx": 1.0, "tau": 0.0, "lam": 0.0}
    if any(abs(counts[k] - expected[k]) > 1e-9 for k in expected):
        print(f"  CHECK FAILED: eigen-decompositions per evaluation {counts}, expected {expected}")
    return sweep_eval, sweep_floor


# --------------------------------------------------------------------------- profile


def profile_mcmc(top: int) -> None:
    """cProfile of one emulator training and one calibration MCMC (virtual wall, 30x25)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))
    from bayescal.calibration.posterior import calibrate
    from bayescal.emulator.assemble import assemble
    from bayescal.emulator.training import train
    from bayescal.mcmc.diagnostics import import_arviz
    from virtual_wall import virtual_experiment

    ve = virtual_experiment(seed=0, runs=30, periods=25)
    a = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, variance=0.99)
    for label, run in (
        (
            "emulator training, 1 chain x 300 sweeps",
            lambda: train(a, n_burn=200, n_draws=100, n_chains=1, seed=1, refine=False),
        ),
    ):
        prof = cProfile.Profile()
        start = time.perf_counter()
        em = prof.runcall(run)
        took = time.perf_counter() - start
        _print_profile(f"{label} ({took:.2f} s, profiled)", prof, top)

    def cal() -> object:
        return calibrate(em, a, n_chains=4, n_burn=500, n_draws=500, seed=3, backend="serial")

    import_arviz()  # imported once per process in real use; keep the import out of the profile

    prof = cProfile.Profile()
    start = time.perf_counter()
    prof.runcall(cal)
    took = time.perf_counter() - start
    _print_profile(
        f"calibration, 4 chains x 1000 sweeps, serial ({took:.2f} s, profiled)", prof, top
    )


def _print_profile(title: str, prof: cProfile.Profile, top: int) -> None:
    out = io.StringIO()
    stats = pstats.Stats(prof, stream=out).strip_dirs().sort_stats("tottime")
    stats.print_stats(top)
    print(f"\n== profile: {title}; top {top} by own time")
    table: dict[tuple[str, int, str], Any] = stats.stats  # type: ignore[attr-defined]
    total = sum(row[2] for row in table.values())
    target = sum(
        row[3]
        for (file, _, name), row in table.items()
        if name == "__call__" and file in ("posterior.py", "gp.py")
    )
    print(
        f"   inside the log posterior (__call__): {target:.2f} s of {total:.2f} s profiled "
        f"({100 * target / total:.0f} %); the rest is the sampler, diagnostics, MAP search"
    )
    lines = out.getvalue().splitlines()
    start = next(i for i, line in enumerate(lines) if line.lstrip().startswith("ncalls"))
    print("\n".join(lines[start : start + top + 1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the paper's size only")
    parser.add_argument("--profile", action="store_true", help="cProfile one MCMC run")
    parser.add_argument("--top", type=int, default=15, help="profile lines to print")
    parser.add_argument("--seed", type=int, default=20240601)
    opts = parser.parse_args()
    rng = np.random.default_rng(opts.seed)
    print(f"BLAS threads: 1; numpy {np.__version__}; ratio = eval / floor (target < 3)")
    for case in CASES[:1] if opts.quick else CASES:
        print(
            f"\n== {case.name}: R={case.n_runs}, m*={case.n_periods}, t={case.n_theta}, "
            f"s={case.n_x}, p={case.n_bases}"
        )
        pb = Problem.draw(case, rng)
        calibration(case, pb, rng)
        training(case, pb, rng)
    if opts.profile:
        profile_mcmc(opts.top)


if __name__ == "__main__":
    main()
