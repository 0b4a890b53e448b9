"""Sequential design: grow the runs where the posterior lies until the emulator is good enough.

``[design] sequential = true`` replaces the one-shot Latin hypercube of the
design stage by a loop (docs/method.md, "Sequential design"; anchors: Damblin
et al. 2018, Sürer, Plumlee and Wild 2024):

1. a first Latin hypercube of ``[design] runs`` runs over the priors' bounds;
2. the runs are simulated (cached per run, in parallel on the study's backend),
   the emulator is trained on every run so far and a short calibration
   (``[calibration]`` chains, at most 300 + 300 sweeps, no extension) gives the
   current posterior. From the second step on in one process, the emulator's MAP
   search starts each basis from the previous step's MAP (a local search: the
   same inputs, a few more runs; :func:`bayescal.emulator.mapfit.find_map`,
   "Warm starts") and the chains start at the previous posterior's draws, spread
   from its centre to its tails (their proposal widths are adapted over the
   whole burn-in as before: a start near the posterior does not tell them). A
   resumed design's first step starts cold. The design
   stage's result is the design only: the emulator stage trains its emulator
   on it with the full search;
3. a batch of ``[design] batch`` runs is chosen among the current posterior's
   draws: the half where the emulator's predictive variance (on the training
   periods, without the out-of-basis part that more runs cannot reduce) is
   largest, spread by a greedy maximin in the posterior's own scale (each
   parameter divided by its posterior SD), away from each other and from the
   runs already made. Before the batch joins the runs, the current emulator's
   mean predictions at its points are kept;
4. the batch is simulated, and the current emulator's **measured** error on it
   (the runs minus the predictions kept in 3, projected on the basis: the
   out-of-basis rest does not shrink with more runs) is turned into the shift
   it would cause in the posterior mean, in posterior SDs (:func:`posterior_shift`:
   the posterior mean's shift ``C J' e / s^2``, ``J`` the emulator's sensitivities
   at the posterior mean, ``C`` the current posterior's covariance, ``s^2`` how
   much its error model widens the white-noise least squares;
   :func:`shift_in_posterior`). The design stops when
   that shift is at most ``[design] tolerance`` and the last two short
   calibrations' SDs agree within :data:`SETTLED` (a posterior a poor emulator
   widens makes any error look small in its own SDs), after three batches without a
   smaller shift (the emulator's error floor: the GP's nugget), at
   ``max_runs`` runs, or once ``max_minutes`` have passed. Otherwise back to 2.

The final design (every run that succeeded: a failed run is said, dropped from
the design and not tried again) is the design stage's result; the later stages
train the emulator and calibrate on it with the study's full settings.

With ``[design] reuse_screening = true`` (:mod:`bayescal.pipeline.reuse`) the
first design is the one-shot design of reuse: the Sobol screening's runs (from
the run cache) then ``[design] runs`` new ones (none with ``runs = 0``); the
emulator's inputs are every parameter, the posterior holds the screened-out ones
at their nominal values, and so does every batch (its rows over every input, the
screened-out ones at their nominal value). ``max_runs`` counts the screening's
runs, the batch's default size the calibrated parameters.

The loop's state is written atomically to ``OUTPUT_DIR/sequential/state.npz``
after each batch is chosen: a killed design resumes with the batch it was
running (its finished runs come from the run cache), and never chooses a batch
twice. ``OUTPUT_DIR/sequential/history.csv`` holds, per step, the runs so far,
the measured emulator error per output, the posterior's mean and SD per
parameter (the runs-to-posterior curve) and the wall seconds of the step's
simulations, emulator and short calibration.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.atomic import atomic_write_npz, atomic_write_text, read_npz
from bayescal.calibration.posterior import Posterior
from bayescal.design import Design, latin_hypercube
from bayescal.errors import ConfigError, DataError
from bayescal.pipeline.reuse import at_nominal, screening_rows
from bayescal.pipeline.sequential import spread_picks
from bayescal.pipeline.stages import (
    Context,
    EmulatorResult,
    build_emulator,
    calibrate_stage,
    make_design,
    simulate,
)
from bayescal.runner import RunResults

__all__ = [
    "HISTORY_FILE",
    "STATE_FILE",
    "STEP_PARTS",
    "Step",
    "batch_differences",
    "chain_starts",
    "choose_batch",
    "error_ratios",
    "posterior_shift",
    "predict_runs",
    "sequential_design",
    "shift_in_posterior",
    "shift_length",
]

Say = Callable[[str], None]
STATE_FILE = Path("sequential") / "state.npz"
HISTORY_FILE = Path("sequential") / "history.csv"
#: Sweeps of the short calibrations inside the loop (burn-in and kept, per chain).
QUICK_SWEEPS = 300
#: The parts of a step whose wall seconds the history records.
STEP_PARTS = ("simulate", "emulator", "calibration")
#: Candidate posterior draws scored for a batch.
CANDIDATES = 400
#: Batches in a row without a new smallest shift after which the design stops: the
#: emulator's error has reached its floor (the GP's nugget), more runs do not help.
PATIENCE = 3
#: Largest relative change of a posterior SD between the last two short calibrations for
#: the posterior to count as settled: a posterior widened by a poor emulator makes any
#: error look small in its own SDs, and it narrows as the runs grow.
SETTLED = 0.2


@dataclass(frozen=True)
class Step:
    """One pass of the loop: the runs it saw and what it measured.

    Attributes
    ----------
    runs
        Design rows of this step (its failed runs included; they are dropped after it).
    succeeded
        Runs that succeeded among them.
    error_ratio
        Output -> the previous emulator's RMSE on the newest batch divided by the
        output's posterior noise SD (NaN for the first design: no batch yet).
    shift
        How far that error would move the posterior mean, in posterior SDs
        (:func:`posterior_shift`; NaN for the first design).
    mean, sd
        Posterior mean and SD of each calibrated parameter (physical units) from
        the short calibration on these runs (NaN where the loop stopped before it).
    seconds
        Wall seconds of the step's main parts: its runs (``simulate``), its emulator
        and its short calibration (empty in a history written before they were
        recorded; the batch's choice and the error measures are not counted).
    """

    runs: int
    succeeded: int
    error_ratio: dict[str, float]
    mean: dict[str, float]
    sd: dict[str, float]
    shift: float = float("nan")
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)


def _quick(ctx: Context) -> Context:
    """The context with a short, unextended calibration for the loop."""
    cal = ctx.study.calibration
    quick = cal.model_copy(
        update={
            "burn": min(cal.burn, QUICK_SWEEPS),
            "samples": min(cal.samples, QUICK_SWEEPS),
            "max_samples": min(cal.samples, QUICK_SWEEPS),
        }
    )
    return dataclasses.replace(ctx, study=ctx.study.model_copy(update={"calibration": quick}))


def chain_starts(post: Posterior, em: EmulatorResult, n_chains: int) -> np.ndarray:
    """Starts ``(n_chains, t)`` (normalised scale) at draws of ``post`` spread from its
    centre to its tails (:func:`bayescal.pipeline.sequential.spread_picks`); the
    parameters it holds fixed are NaN (their own start)."""
    flat = post.draws.reshape(-1, len(post.names))
    order = [post.names.index(n) for n in em.emulator.parameter_names]
    unit = em.assembled.theta_normaliser.apply(flat[:, order])
    starts = unit[spread_picks(np.clip(unit, 0.0, 1.0), n_chains)]
    held = [k for k, n in enumerate(em.emulator.parameter_names) if n in post.held_names]
    starts[:, held] = np.nan
    return starts


def _noise_sd(post: Posterior, em: EmulatorResult, ctx: Context) -> dict[str, float]:
    """Each calibrated output's posterior median noise SD (on the emulator's scale)."""
    found = {name: float(np.median(draws)) for name, draws in post.noise_sd().items()}
    for name in em.emulator.outputs.names:
        if name not in found:
            stated = ctx.study.outputs.noise_sd(name)
            if stated is None:
                raise ConfigError(
                    f"the sequential design needs a noise SD for {name!r}: the calibration "
                    "gave none and [outputs] states none",
                    hint="set the output's noise_sd, or design.sequential = false",
                )
            found[name] = float(min(stated)) if isinstance(stated, tuple) else float(stated)
    return found


def predict_runs(em: EmulatorResult, theta_phys: np.ndarray) -> np.ndarray:
    """The emulator's mean on the training periods at each parameter set.

    Returns ``(b, N, m*)``: outputs stacked along ``N`` (``outputs.slices``), on the
    emulator's scale (the outputs' units, or log units for log-transformed outputs).
    """
    x = em.emulator.x
    out = []
    for theta in np.atleast_2d(theta_phys):
        mean, _ = em.emulator.predict(theta, x, out_of_basis=False)
        out.append(mean)
    return np.asarray(out)


def batch_differences(
    em: EmulatorResult, predicted: np.ndarray, rows: np.ndarray, sims: RunResults
) -> np.ndarray:
    """Runs minus the predictions made before they were run, in the basis.

    The difference is standardised and projected on the basis of ``em`` (the
    emulator trained on every run, the batch's included): the out-of-basis rest of
    a run (the truncation of the PCA, which the calibration carries as
    ``1 / lambda``) does not shrink with more runs.

    Parameters
    ----------
    em
        The emulator trained on every run, the batch's included.
    predicted
        ``(b, N, m*)`` predictions made before the batch was run (:func:`predict_runs`).
    rows
        Design rows of the batch (in ``sims.design``).
    sims
        The runs; a failed batch row is skipped.

    Returns
    -------
    ``(b_ok, N, m*)`` on the emulator's scale (the outputs' units, or log units).
    """
    asm = em.assembled
    n_per = asm.x.shape[0]
    phys = asm.outputs.invert(asm.y_std)  # (N, R_ok m*), run-major
    sd = asm.outputs.sd[:, None]
    k = asm.basis.k
    where = {int(row): i for i, row in enumerate(sims.indices)}
    out = []
    for b, row in enumerate(rows):
        i = where.get(int(row))
        if i is None:
            continue
        diff = np.nan_to_num((phys[:, i * n_per : (i + 1) * n_per] - predicted[b]) / sd)
        out.append(k @ np.linalg.lstsq(k, diff, rcond=None)[0] * sd)
    return np.asarray(out).reshape(len(out), *predicted.shape[1:])


def error_ratios(
    em: EmulatorResult, diffs: np.ndarray, noise: dict[str, float]
) -> dict[str, float]:
    """Each output's RMS of :func:`batch_differences` over its noise SD."""
    return {
        name: float(np.sqrt(np.mean(diffs[:, sl] ** 2)) / noise[name]) if len(diffs) else np.nan
        for name, sl in em.assembled.outputs.slices.items()
    }


def posterior_shift(
    em: EmulatorResult,
    diffs: np.ndarray,
    noise: dict[str, float],
    mean: dict[str, float],
    sd: dict[str, float],
    covariance: np.ndarray | None = None,
) -> float:
    """How far the emulator's measured error would move the posterior mean, in posterior SDs.

    ``J = d eta / d theta`` is the outputs' sensitivities, each row over its noise
    SD, the emulator's by central differences of half a posterior SD around the
    posterior mean, over the training periods. With ``covariance`` (the current
    posterior's, physical units, over the parameters whose ``sd`` is above zero,
    in the order of ``em.emulator.parameter_names``) the shift is the posterior
    mean's, ``C J' e / s^2``, measured in ``C`` (:func:`shift_in_posterior`: AR(1)
    errors, a discrepancy and the emulator's own variance widen the posterior
    beyond the white-noise least squares, and a prior bounds what the data
    hardly inform). Without it, the white-noise least squares' ``|P_J e|``
    (:func:`shift_length`: a state saved by an earlier bayescal holds no
    covariance). Parameters held fixed (``sd`` zero: ``[design]
    reuse_screening``'s screened-out inputs) are left out of ``J``. Returns the
    root mean square over the batch (NaN for an empty batch).
    """
    if not len(diffs):
        return float("nan")
    names = em.emulator.parameter_names
    free = [j for j, n in enumerate(names) if _varies(sd.get(n, 0.0), mean[n])]
    scale = np.empty(diffs.shape[1])
    for name, sl in em.assembled.outputs.slices.items():
        scale[sl] = noise[name]
    center = np.array([mean[n] for n in names])
    cols = []
    for j in free:
        h = np.zeros_like(center)
        h[j] = 0.5 * sd[names[j]]
        up, down = predict_runs(em, np.vstack([center + h, center - h]))
        cols.append(((up - down) / scale[:, None]).ravel() / (2 * h[j]))
    errors = (diffs / scale[None, :, None]).reshape(len(diffs), -1)
    if covariance is None or np.shape(covariance) != (len(free), len(free)):
        # no covariance (a state of an earlier bayescal), or over other parameters
        return shift_length(np.column_stack(cols), errors)
    return shift_in_posterior(np.column_stack(cols), errors, covariance)


def shift_length(sensitivity: np.ndarray, errors: np.ndarray) -> float:
    """Root mean square over rows of ``|P_J e|``: the Mahalanobis length of the shift.

    Parameters
    ----------
    sensitivity
        ``J`` ``(n, t)``: the outputs' derivatives in the parameters, each row
        divided by its noise SD.
    errors
        ``(b, n)``: one error vector per row, divided by the noise SD likewise.
    """
    q, _ = np.linalg.qr(np.asarray(sensitivity, dtype=float))
    e = np.atleast_2d(np.asarray(errors, dtype=float))
    return float(np.sqrt(np.mean(np.sum((e @ q) ** 2, axis=1))))


def shift_in_posterior(
    sensitivity: np.ndarray, errors: np.ndarray, covariance: np.ndarray
) -> float:
    """Root mean square over rows of the posterior mean's shift, in the posterior's SDs.

    The posterior is read as a Gaussian likelihood of precision ``J'J / s^2``
    (white errors whose variance the calibration's error model inflates by
    ``s^2``: AR(1) errors, a discrepancy, the emulator's variance) times a prior
    that holds what the data leave open, ``C^-1 = J'J / s^2 + P``. ``s^2`` is the
    smallest inflation that leaves ``P`` positive semi-definite, the largest
    eigenvalue of ``L' J'J L`` (``C = L L'``), and at least 1 (``J`` is scaled by
    the noise SD; an error model only widens: where a prior informs every
    direction the eigenvalue is below ``s^2``). An error ``e`` then moves the mean
    by ``Delta = C J' e / s^2``, of Mahalanobis length ``|L' J' e| / s^2``: the
    white-noise least squares' ``|P_J e|`` where ``C = (J'J)^-1``, that shift
    over ``s`` where ``C`` is ``s^2`` times wider, and bounded by the prior along a
    direction the data hardly inform (where the least-squares shift is not).

    ``sensitivity`` and ``errors`` are those of :func:`shift_length`;
    ``covariance`` ``(t, t)`` is the posterior's covariance of the parameters.
    Returns ``sqrt(mean_b |L' J' e_b|^2) / s^2``.
    """
    jac = np.asarray(sensitivity, dtype=float)
    e = np.atleast_2d(np.asarray(errors, dtype=float))
    cov = np.atleast_2d(np.asarray(covariance, dtype=float))
    chol = np.linalg.cholesky(cov + 1e-12 * np.diag(np.diag(cov)))
    jl = jac @ chol  # (n, t)
    # at least 1: J is scaled by the noise SD, and an error model only widens
    inflation = max(float(np.linalg.eigvalsh(jl.T @ jl)[-1]), 1.0)
    z = (e @ jl) / inflation  # (b, t): L' J' e_b / s^2
    return float(np.sqrt(np.mean(np.sum(z**2, axis=1))))


def _variance(em: EmulatorResult, unit: np.ndarray) -> np.ndarray:
    """Mean predictive variance of the standardised output over the training periods,
    without the out-of-basis part, at each normalised parameter set."""
    x = em.emulator.x
    return np.array(
        [float(np.mean(em.emulator.predict_std(u, x, out_of_basis=False)[1])) for u in unit]
    )


def choose_batch(
    em: EmulatorResult, post: Posterior, existing: np.ndarray, size: int, seed: int
) -> np.ndarray:
    """``size`` normalised parameter sets among the posterior's draws (module docstring).

    The spread is measured over the coordinates the posterior samples: one it holds at
    a value (``reuse_screening``'s screened-out inputs) is left out, so that a run with
    other values of those (a screening run) is near a draw with its sampled values.

    Parameters
    ----------
    em
        The current emulator.
    post
        The current posterior.
    existing
        Normalised rows already in the design, ``(R, t)``.
    size
        Runs in the batch.
    seed
        Seed of the thinning of the draws.
    """
    draws = post.unit_draws.reshape(-1, len(post.names))
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(draws), size=min(CANDIDATES, len(draws)), replace=False)
    cand = np.unique(draws[pick], axis=0)
    var = _variance(em, cand)
    keep = var >= np.median(var)
    cand, var = cand[keep], var[keep]
    held = post.held_names  # at one value in every draw
    free = np.array([n not in held for n in post.names])
    if not free.any():
        free[:] = True
    if not free.any():
        free[:] = True
    scale = np.maximum(draws[:, free].std(axis=0), 1e-9)
    z_cand = cand[:, free] / scale
    z_old = np.asarray(existing, dtype=float).reshape(-1, len(free))[:, free] / scale
    near = (
        np.min(np.linalg.norm(z_cand[:, None, :] - z_old[None, :, :], axis=2), axis=1)
        if len(z_old)
        else np.full(len(cand), np.inf)
    )
    chosen: list[int] = [int(np.argmax(var))]
    while len(chosen) < min(size, len(cand)):
        last = z_cand[chosen[-1]]
        near = np.minimum(near, np.linalg.norm(z_cand - last, axis=1))
        near[chosen] = -np.inf
        chosen.append(int(np.argmax(near)))
    return np.asarray(cand[chosen], dtype=float)


def _posterior_summary(post: Posterior) -> tuple[dict[str, float], dict[str, float]]:
    flat = post.draws.reshape(-1, len(post.names))
    return (
        {n: float(v) for n, v in zip(post.names, flat.mean(axis=0), strict=True)},
        {n: float(v) for n, v in zip(post.names, flat.std(axis=0), strict=True)},
    )


def _varies(sd: Any, mean: Any) -> Any:
    """Whether a posterior SD is above rounding (a held parameter's is zero or ~1e-17)."""
    return np.asarray(sd) > 1e-9 * (np.abs(mean) + 1e-300)


def _free_covariance(post: Posterior, names: tuple[str, ...]) -> np.ndarray:
    """The posterior's covariance over ``names`` that vary (not held fixed)."""
    flat = post.draws.reshape(-1, len(post.names))
    held = post.held_names
    cols = [post.names.index(n) for n in names if n in post.names and n not in held]
    return np.atleast_2d(np.cov(flat[:, cols], rowvar=False))


@dataclass
class _State:
    """What the loop has decided so far (written after each batch is chosen)."""

    key: str
    unit: np.ndarray  # every row so far, normalised
    batch_start: int  # first row of the newest batch (== len(unit) before any batch)
    predicted: np.ndarray  # (b, N, m*) predictions at the newest batch, or empty
    steps: list[Step]
    started: float  # seconds of design already spent before this process
    noise: dict[str, float] = dataclasses.field(default_factory=dict)  # at the newest batch
    cov: np.ndarray | None = None  # the posterior's covariance when the newest batch was chosen

    def save(self, out: Path, outputs: tuple[str, ...], names: tuple[str, ...]) -> None:
        atomic_write_npz(
            out / STATE_FILE,
            {
                "key": np.asarray(self.key),
                "unit": self.unit,
                "batch_start": np.asarray(self.batch_start),
                "predicted": self.predicted,
                "seconds": np.asarray(self.started),
                "noise_names": np.asarray(list(self.noise), dtype=str),
                "noise": np.asarray(list(self.noise.values()), dtype=float),
                "cov": np.empty((0, 0)) if self.cov is None else self.cov,
            },
        )
        atomic_write_text(out / HISTORY_FILE, _history_csv(self.steps, outputs, names))

    @classmethod
    def load(cls, out: Path, key: str) -> _State | None:
        path = out / STATE_FILE
        if not path.is_file():
            return None
        try:
            data = read_npz(path)
            if str(data["key"]) != key:
                return None
            steps = _read_history(out / HISTORY_FILE)
            return cls(
                key,
                np.asarray(data["unit"], dtype=float),
                int(data["batch_start"]),
                np.asarray(data["predicted"], dtype=float),
                steps,
                float(data["seconds"]),
                {str(n): float(v) for n, v in zip(data["noise_names"], data["noise"], strict=True)},
                np.asarray(data["cov"], dtype=float) if "cov" in data else None,
            )
        except (OSError, ValueError, KeyError, DataError):
            return None


def _history_csv(steps: list[Step], outputs: tuple[str, ...], names: tuple[str, ...]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(
        ["runs", "succeeded"]
        + ["shift"]
        + [f"error_ratio_{o}" for o in outputs]
        + [f"mean_{n}" for n in names]
        + [f"sd_{n}" for n in names]
        + [f"seconds_{part}" for part in STEP_PARTS]
    )
    for s in steps:
        writer.writerow(
            [s.runs, s.succeeded]
            + [f"{s.shift:.6g}"]
            + [f"{s.error_ratio.get(o, float('nan')):.6g}" for o in outputs]
            + [f"{s.mean.get(n, float('nan')):.8g}" for n in names]
            + [f"{s.sd.get(n, float('nan')):.8g}" for n in names]
            + [f"{s.seconds.get(part, float('nan')):.4g}" for part in STEP_PARTS]
        )
    return buf.getvalue()


def _read_history(path: Path) -> list[Step]:
    if not path.is_file():
        return []
    steps = []
    with path.open(encoding="utf-8") as f:
        for row in csv.DictReader(f):

            def pick(prefix: str, row: dict[str, str] = row) -> dict[str, float]:
                return {k[len(prefix) :]: float(v) for k, v in row.items() if k.startswith(prefix)}

            steps.append(
                Step(
                    int(row["runs"]),
                    int(row["succeeded"]),
                    pick("error_ratio_"),
                    pick("mean_"),
                    pick("sd_"),
                    float(row["shift"]),
                    pick("seconds_"),
                )
            )
    return steps


def sequential_design(ctx: Context, key: str, say: Say) -> tuple[Design, list[Step]]:
    """Grow the design in batches (module docstring); the final design and the steps.

    Parameters
    ----------
    ctx
        The study.
    key
        The design stage's key: a saved state with another key is not resumed.
    say
        Receives one line per step.
    """
    section = ctx.study.design
    priors = ctx.priors
    names = tuple(priors)
    seed = ctx.seed("design", section.seed)
    cap = section.run_cap(screening_rows(ctx.study))  # the screening's runs count
    size = section.batch_size(len(ctx.study.calibrated))
    quick = _quick(ctx)
    previous: tuple[EmulatorResult, Posterior] | None = None  # this process's last step
    state = _State.load(ctx.out, key)
    if state is None:
        first = (
            make_design(ctx)  # the screening's runs, then the new ones (reuse's design)
            if section.reuse_screening
            else latin_hypercube(
                priors, section.runs, seed, None if section.optimization == "none" else "random-cd"
            )
        )
        state = _State(key, first.unit, len(first.unit), np.empty((0,)), [], 0.0)
    else:
        say(
            f"design: resuming the sequential design at {len(state.unit)} runs "
            f"({len(state.steps)} step(s) done)"
        )
    clock = time.perf_counter() - state.started
    outputs = tuple(ctx.study.outputs.calibrate)
    while True:
        design = Design(priors, state.unit, seed=seed)
        seconds: dict[str, float] = {}
        tick = time.perf_counter()
        sims = simulate(ctx, design)
        seconds["simulate"] = time.perf_counter() - tick
        tick = time.perf_counter()
        em = build_emulator(quick, sims, warm=None if previous is None else previous[0])
        seconds["emulator"] = time.perf_counter() - tick
        ratio: dict[str, float] = {o: float("nan") for o in outputs}
        shift = float("nan")
        batch_rows = np.arange(state.batch_start, len(state.unit))
        if state.predicted.size and len(batch_rows) and state.steps:
            diffs = batch_differences(em, state.predicted, batch_rows, sims)
            ratio = error_ratios(em, diffs, state.noise)
            last = state.steps[-1]
            cov = state.cov if state.cov is not None and state.cov.size else None
            shift = posterior_shift(em, diffs, state.noise, last.mean, last.sd, cov)
        done = bool(np.isfinite(shift)) and shift <= section.tolerance and _settled(state.steps)
        failed = [f.index for f in sims.failures]
        if failed:  # dropped: the runner would try them again at every step
            say(
                f"design: {len(failed)} run(s) failed and are dropped from the design (their "
                f"errors in {ctx.out / 'simulations' / 'failures'}); the design goes on"
            )
            keep = np.setdiff1d(np.arange(len(state.unit)), failed)
            state.unit = state.unit[keep]
            state.batch_start -= int(np.sum(np.asarray(failed) < state.batch_start))
        minutes = (time.perf_counter() - clock) / 60.0
        over_time = section.max_minutes is not None and minutes >= section.max_minutes
        full = len(state.unit) >= cap
        shifts = [st.shift for st in state.steps if np.isfinite(st.shift)]
        if np.isfinite(shift):
            shifts.append(shift)
        stalled = len(shifts) > PATIENCE and min(shifts[-PATIENCE:]) >= min(shifts[:-PATIENCE])
        mean: dict[str, float] = {}
        sd: dict[str, float] = {}
        post: Posterior | None = None
        if not (done or full or over_time or stalled):
            tick = time.perf_counter()
            if previous is None:
                post = calibrate_stage(quick, em)
            else:
                starts = chain_starts(previous[1], em, quick.study.calibration.chains)
                post = calibrate_stage(quick, em, starts=starts)
            mean, sd = _posterior_summary(post)
            seconds["calibration"] = time.perf_counter() - tick
        step = Step(design.runs, len(sims.indices), ratio, mean, sd, shift, seconds)
        state.steps.append(step)
        say(_step_line(step, section.tolerance, names))
        if done or full or over_time or stalled or post is None:
            why = (
                f"the emulator's error on the newest batch would move the posterior mean by "
                f"{shift:.2g} posterior SD, within tolerance = {section.tolerance:g}, and the "
                f"posterior's SDs changed by less than {SETTLED:.0%} with the batch before"
                if done
                else f"max_runs = {cap} reached"
                if full
                else f"max_minutes = {section.max_minutes:g} reached"
                if over_time
                else f"the shift has not fallen below {min(shifts):.2g} in {PATIENCE} batches: "
                "the emulator's error is at its floor, more runs do not reduce it"
            )
            say(f"design: sequential design stopped at {len(state.unit)} runs ({why})")
            state.started = time.perf_counter() - clock
            state.predicted = np.empty((0,))
            state.batch_start = len(state.unit)
            state.save(ctx.out, outputs, names)
            return Design(priors, state.unit, seed=seed), state.steps
        previous = (em, post)
        noise = _noise_sd(post, em, ctx)
        batch = choose_batch(
            em, post, state.unit, min(size, cap - len(state.unit)), seed + len(state.steps)
        )
        batch = at_nominal(ctx.study, batch)  # the screened-out inputs exactly at nominal
        physical = em.assembled.theta_normaliser.invert(batch)
        state.predicted = predict_runs(em, physical)
        state.noise = noise
        state.cov = _free_covariance(post, em.emulator.parameter_names)
        state.batch_start = len(state.unit)
        state.unit = np.vstack([state.unit, batch])
        state.started = time.perf_counter() - clock
        state.save(ctx.out, outputs, names)


def _settled(steps: list[Step]) -> bool:
    """Whether the last two short calibrations' SDs agree within :data:`SETTLED` (each
    parameter that varies)."""
    with_posterior = [st for st in steps if st.sd]
    if len(with_posterior) < 2:
        return False
    before, last = with_posterior[-2], with_posterior[-1]
    for name, sd in last.sd.items():
        old = before.sd.get(name, float("nan"))
        if _varies(sd, last.mean[name]) and not abs(sd / old - 1.0) <= SETTLED:
            return False
    return True


def _step_line(step: Step, tolerance: float, names: tuple[str, ...]) -> str:
    text = f"design: {step.runs} runs ({step.succeeded} succeeded)"
    if np.isfinite(step.shift):
        errors = [f"{o} {r:.2f}" for o, r in step.error_ratio.items() if np.isfinite(r)]
        text += (
            f"; the emulator's error on the newest batch ({', '.join(errors)} x noise SD) "
            f"would move the posterior mean {step.shift:.2f} SD (stops at {tolerance:g})"
        )
    if step.seconds:
        text += " [" + ", ".join(f"{k} {v:.0f} s" for k, v in step.seconds.items()) + "]"
    if step.mean:
        text += "; posterior " + ", ".join(
            f"{n} {step.mean[n]:.4g} ± {step.sd[n]:.2g}"
            for n in names
            if _varies(step.sd[n], step.mean[n])  # not the held-fixed ones
        )
    return text
