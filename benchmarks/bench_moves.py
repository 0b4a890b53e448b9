"""Gibbs sweeps against joint moves on the Twin House calibration (issue 18).

The Twin House example (Annex 58 wall, AR(1) errors, five parameters) is
copied and run up to its emulator (``scripts/run_case_studies.py`` points it
at the shared data; skipped with a message where they are missing). Its
calibration target (eq. 16 with AR(1) errors, ``lambda``, ``lambda*`` and
``phi`` sampled) is then sampled in this one process, one after the other, by

* ``moves = "gibbs"``: every sweep moves each of the 8 coordinates once, then
  theta* jointly (9 log-density evaluations a sweep);
* ``moves = "joint"``: from halfway through burn-in theta*, ``lambda*`` and
  ``phi`` move only together, 7 times a sweep, ``lambda`` alone (8 a sweep),

each with 4 chains in worker processes. Printed per variant: wall seconds,
log-density evaluations after burn-in (counted from the schedule), the largest
R-hat, the smallest bulk and tail ESS, the smallest bulk ESS per evaluation
after burn-in and per second; then the ratios joint / gibbs.

The lengths differ on purpose (the Gibbs sweeps need many more to reach a
usable ESS): ``--gibbs BURN SAMPLES`` and ``--joint BURN SAMPLES``, defaults
2000 + 4000 (the example's settings before joint moves) and 600 + 1000 (its
settings now). BLAS and OpenMP are single-threaded.

Run::

    .venv/bin/python benchmarks/bench_moves.py
    .venv/bin/python benchmarks/bench_moves.py --gibbs 1000 2000 --joint 600 600
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

from run_case_studies import CaseError, prepare_case  # noqa: E402

from bayescal.calibration.target import build_target, default_sampler, sample  # noqa: E402
from bayescal.config import load_study  # noqa: E402
from bayescal.mcmc.diagnostics import diagnose  # noqa: E402
from bayescal.pipeline import Options, run  # noqa: E402


def _evaluations(sampler: object, n_draws: int, d: int) -> int:
    """Log-density evaluations of one chain after burn-in."""
    after = int(getattr(sampler, "joint_after_burn", 0))
    joint = len(getattr(sampler, "joint", ()))
    per_sweep = (d - joint + after) if after else (d + (1 if joint else 0))
    return n_draws * per_sweep


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gibbs", nargs=2, type=int, default=[2000, 4000], metavar=("BURN", "N"))
    parser.add_argument("--joint", nargs=2, type=int, default=[600, 1000], metavar=("BURN", "N"))
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        try:
            folder = prepare_case("twinhouse", Path(tmp) / "twinhouse")
        except CaseError as exc:
            print(f"skipped: {exc}")
            return 0
        study = load_study(folder)
        res = run(study, until="emulator", options=Options(), say=lambda _: None)
        em, a, ctx = res.emulator, res.emulator.assembled, res.context
        priors = list(ctx.priors.values())
        target = build_target(
            em.emulator, a.w_star, a.lam_star_prior, priors, observations=a.observations
        )
        names = [*ctx.priors, *target.aux_names]
        rows = {}
        for moves, (burn, n_draws) in (("gibbs", args.gibbs), ("joint", args.joint)):
            sampler = default_sampler(target, burn, moves)  # type: ignore[arg-type]
            start = time.perf_counter()
            chains = sample(
                target, n_draws, n_burn=burn, n_chains=4, seed=args.seed, backend="processes",
                sampler=sampler,
            )  # fmt: skip
            seconds = time.perf_counter() - start
            diag = diagnose(chains.draws, names)
            evals = 4 * _evaluations(sampler, n_draws, target.d)
            ess = float(np.min(diag.ess_bulk))
            rows[moves] = {
                "sweeps": f"4 x ({burn} + {n_draws})",
                "seconds": seconds,
                "evaluations after burn-in": evals,
                "max R-hat": float(np.max(diag.rhat)),
                "min bulk ESS": ess,
                "min tail ESS": float(np.min(diag.ess_tail)),
                "slowest": names[int(np.argmin(diag.ess_bulk))],
                "min bulk ESS per 1000 evaluations": 1000.0 * ess / evals,
                "min bulk ESS per second": ess / seconds,
            }
    print(f"Twin House calibration, 4 chains in worker processes, seed {args.seed}")
    keys = list(rows["gibbs"])
    width = max(len(k) for k in keys)
    print(f"{'':{width}}  {'gibbs':>14}  {'joint':>14}")
    for key in keys:
        cells = []
        for moves in ("gibbs", "joint"):
            value = rows[moves][key]
            cells.append(f"{value:>14.4g}" if isinstance(value, float) else f"{value!s:>14}")
        print(f"{key:{width}}  {cells[0]}  {cells[1]}")
    for key in ("min bulk ESS per 1000 evaluations", "min bulk ESS per second"):
        ratio = float(rows["joint"][key]) / float(rows["gibbs"][key])  # type: ignore[arg-type]
        print(f"joint / gibbs, {key}: {ratio:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
