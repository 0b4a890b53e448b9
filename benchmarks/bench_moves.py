"""Gibbs sweeps against joint moves on the Twin House calibration (issue 18).

The Twin House example (Annex 58 wall, AR(1) errors, five parameters) is
copied and run up to its emulator (``scripts/run_case_studies.py`` points it
at the shared data; skipped with a message where they are missing). Its
calibration target (eq. 16 with AR(1) errors, ``lambda``, ``lambda*`` and
``phi`` sampled) is then sampled in this one process, one after the other, by

* ``moves = "gibbs"``: every sweep moves each of the 8 coordinates once, then
  theta* jointly (9 log-density evaluations a sweep);
* ``joint, unscreened``: from halfway through burn-in theta*, ``lambda*`` and
  ``phi`` move only together, 7 times a sweep, ``lambda`` alone (8 a sweep);
* ``moves = "joint"`` as shipped: the same, each joint proposal first screened
  by the stand-in learnt during burn-in (delayed acceptance), so that only those
  that pass are evaluated,

each with 4 chains in worker processes. Printed per variant: wall seconds,
log-density evaluations after burn-in (counted from the schedule and the
chains' screened shares), the largest R-hat, the smallest bulk and tail ESS,
the smallest bulk ESS per evaluation after burn-in and per second; then the
ratios of each to the Gibbs sweeps and of the screened to the unscreened joint
moves.

The lengths differ on purpose (the Gibbs sweeps need many more to reach a
usable ESS): ``--gibbs BURN SAMPLES`` and ``--joint BURN SAMPLES``, defaults
2000 + 4000 (the example's settings before joint moves) and 600 + 1000 (its
settings now, for both joint variants). BLAS and OpenMP are single-threaded.

Run::

    .venv/bin/python benchmarks/bench_moves.py
    .venv/bin/python benchmarks/bench_moves.py --gibbs 1000 2000 --joint 600 600
    .venv/bin/python benchmarks/bench_moves.py --example box-freefloat \
        --gibbs 2500 2500 --joint 1000 2000

``--example`` takes the boxes' targets instead (AR(1) errors with a discrepancy in
the likelihood: four parameters, ``lambda*``, ``phi`` and ``r`` in the joint block).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
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


def _evaluations(sampler: object, n_draws: int, d: int, screened: float | None) -> float:
    """Log-density evaluations of one chain after burn-in (``screened``: the share of
    its joint proposals the screen turned down unseen)."""
    after = int(getattr(sampler, "joint_after_burn", 0))
    joint = len(getattr(sampler, "joint", ()))
    moves = after if after else (1 if joint else 0)
    alone = (d - joint) if after else d
    return n_draws * (alone + moves * (1.0 - (screened or 0.0)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gibbs", nargs=2, type=int, default=[2000, 4000], metavar=("BURN", "N"))
    parser.add_argument("--joint", nargs=2, type=int, default=[600, 1000], metavar=("BURN", "N"))
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument(
        "--example",
        default="twinhouse",
        choices=["twinhouse", "box-coheating", "box-freefloat"],
        help="whose calibration target (default: twinhouse)",
    )
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        try:
            folder = prepare_case(args.example, Path(tmp) / args.example)
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
        variants = (
            ("gibbs", "gibbs", args.gibbs),
            ("joint, unscreened", "joint", args.joint),
            ("joint", "joint", args.joint),
        )
        for label, moves, (burn, n_draws) in variants:
            sampler = default_sampler(target, burn, moves)  # type: ignore[arg-type]
            if label == "joint, unscreened":
                sampler = dataclasses.replace(sampler, screen=False)
            start = time.perf_counter()
            chains = sample(
                target, n_draws, n_burn=burn, n_chains=4, seed=args.seed, backend="processes",
                sampler=sampler,
            )  # fmt: skip
            seconds = time.perf_counter() - start
            diag = diagnose(chains.draws, names)
            evals = sum(
                _evaluations(sampler, n_draws, target.d, r.screened) for r in chains.results
            )
            ess = float(np.min(diag.ess_bulk))
            screened = [r.screened for r in chains.results if r.screened is not None]
            rows[label] = {
                "sweeps": f"4 x ({burn} + {n_draws})",
                "seconds": seconds,
                "evaluations after burn-in": evals,
                "screened share": float(np.mean(screened)) if screened else float("nan"),
                "max R-hat": float(np.max(diag.rhat)),
                "min bulk ESS": ess,
                "min tail ESS": float(np.min(diag.ess_tail)),
                "slowest": names[int(np.argmin(diag.ess_bulk))],
                "min bulk ESS per 1000 evaluations": 1000.0 * ess / evals,
                "min bulk ESS per second": ess / seconds,
            }
    print(f"{args.example} calibration, 4 chains in worker processes, seed {args.seed}")
    keys = list(rows["gibbs"])
    width = max(len(k) for k in keys)
    print(f"{'':{width}}" + "".join(f"  {label:>18}" for label in rows))
    for key in keys:
        cells = []
        for label in rows:
            value = rows[label][key]
            cells.append(f"{value:>18.4g}" if isinstance(value, float) else f"{value!s:>18}")
        print(f"{key:{width}}" + "".join(f"  {c}" for c in cells))
    pairs = (("joint", "gibbs"), ("joint, unscreened", "gibbs"), ("joint", "joint, unscreened"))
    for key in ("min bulk ESS per 1000 evaluations", "min bulk ESS per second"):
        for top, bottom in pairs:
            ratio = float(rows[top][key]) / float(rows[bottom][key])  # type: ignore[arg-type]
            print(f"{top} / {bottom}, {key}: {ratio:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
