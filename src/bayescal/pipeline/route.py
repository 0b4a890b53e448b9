"""``[predict] method = "auto"``: the emulator's bands where it is measured good enough.

The simulator route re-runs the simulator at ``[predict] runs`` posterior draws;
the emulator route makes no run. ``auto`` decides by measurement, not by
assumption: the simulator is run at ``[predict] check_runs`` of those draws (a
subset of the simulator route's own draws, so that these runs are reused from
the run cache if the simulator route is taken), and the emulator's mean at the
same draws (conditioned on the design runs over the test window, as the
emulator route's is: :func:`bayescal.pipeline.predict.emulator_with_test_window`)
is compared with their part on the output basis (what the emulator predicts: its
band holds the part off the basis apart) on the test window. Those runs are held
out: the emulator never saw them. When the root mean squared difference of every
calibrated output is at most ``[predict] check_tolerance`` times the output's
noise SD (with ``off_basis = "check_runs"``, the default, the noise the completed
band uses, estimated again from the held-out runs; with ``"none"`` the
calibration's posterior noise SD, from lambda*, which also holds the part off
the basis and so reads each error smaller), the emulator route gives the bands;
otherwise the simulator route does. Without
a test window the training periods are compared instead.

With an emulator error of ``c`` noise SDs the band's centre is off by about
``c`` SDs of the noise; at ``c = 0.3`` a 95 % band of noise alone would cover
about 94 %: the default tolerance.

The same runs also measure the emulator's centre against the whole held-out runs
(:attr:`RouteCheck.centre`): the part off the output basis is not in it. With
``[predict] off_basis = "check_runs"`` (the default) the emulator route completes
its centre with those runs' mean part off the basis
(:mod:`bayescal.pipeline.completed`), measured held out (each run against the
other runs' mean part, :attr:`RouteCheck.completed`); with ``"none"`` the band
holds that part apart. Where the centre's error (completed or not) exceeds the
tolerance on the emulator route, the run warns that its point metrics (RMSE,
CV(RMSE)) will be worse than the simulator route's (on the office example, left
on the basis, hourly gas CV(RMSE) 18.3 % on the held-out week against 6.0 % from
the simulator route at the same posterior, both routes' 95 % bands covering
0.93-0.99 of the week: docs/validation/case-studies-log.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bayescal.calibration.posterior import Posterior
from bayescal.design import Design
from bayescal.pipeline.predict import (
    emulator_with_test_window,
    period_moments,
    place_periods,
    predicted_parts,
    thin_draws,
)
from bayescal.pipeline.simnoise import simulator_noise
from bayescal.pipeline.stages import Context, EmulatorResult, level_values, simulate

__all__ = ["RouteCheck", "check_route"]


@dataclass(frozen=True)
class RouteCheck:
    """What ``method = "auto"`` measured and chose.

    Attributes
    ----------
    route
        ``"emulator"`` or ``"simulator"``.
    ratio
        Output -> the emulator's RMS error at the held-out runs over the output's
        noise SD (which noise: below).
    runs
        Held-out runs that succeeded.
    window
        ``"test"`` (the test window) or ``"train"`` (no test window).
    tolerance
        ``[predict] check_tolerance``.
    centre
        Output -> the RMS difference between the emulator's centre and the whole
        held-out runs (the part off the output basis included) over the output's
        noise SD.
    completed
        Output -> the same for the centre completed with the part off the basis,
        each run's centre with the *other* held-out runs' mean part (held out;
        at least two runs).
    off_basis
        Output -> the mean over the held-out runs of their part off the output
        basis, and the variance of one more run's part about it (the sample
        variance times ``1 + 1/n``), ``(n_total,)`` each on the level scale of
        the calibration (NaN outside the training periods and the test
        window): what completes the emulator route's centre
        (:func:`bayescal.pipeline.completed.completed_band`); empty with
        ``[predict] off_basis = "none"`` or fewer than two runs.
    skipped
        ``off_basis = "check_runs"`` asked for the completion but fewer than two
        held-out runs succeeded: the centre stays on the basis (the line says so).

    With the completion asked for (and two runs or more) every ratio is over the
    noise SD the completed band uses, estimated again from the held-out runs'
    residuals on the training periods (:func:`bayescal.pipeline.simnoise.simulator_noise`);
    otherwise over the calibration's (from ``lambda*``, which also holds the part
    off the basis).
    """

    route: str
    ratio: dict[str, float]
    runs: int
    window: str
    tolerance: float
    centre: dict[str, float] = field(default_factory=dict)
    completed: dict[str, float] = field(default_factory=dict)
    off_basis: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    skipped: bool = False

    @property
    def completes(self) -> bool:
        """Whether the emulator route's centre is completed with the runs' part off the
        basis (``[predict] off_basis = "check_runs"`` and at least two held-out runs)."""
        return self.route == "emulator" and bool(self.off_basis)

    def line(self) -> str:
        """One line for the terminal and the log."""
        worst = ", ".join(f"{o} {r:.2f}" for o, r in self.ratio.items())
        return (
            f"predict: method = 'auto' chose the {self.route} route: the emulator's error at "
            f"{self.runs} held-out runs at posterior draws on the {self.window} window is "
            f"{worst} x the noise SD (emulator at most {self.tolerance:g})"
            + (
                f"; its centre is completed with those runs' mean part off the output basis "
                f"(held out: {', '.join(f'{o} {c:.2f}' for o, c in self.completed.items())} "
                "x the noise SD)"
                if self.completes
                else ""
            )
            + (
                "; its centre is NOT completed off the output basis: fewer than two held-out "
                "runs succeeded"
                if self.skipped and self.route == "emulator"
                else ""
            )
        )

    def warning(self) -> str | None:
        """A warning where the emulator route's centre misses the whole runs by more than
        the tolerance (the part off the output basis), else ``None``."""
        figures = self.completed if self.completes else self.centre
        over = {o: c for o, c in figures.items() if c > self.tolerance}
        if self.route != "emulator" or not over:
            return None
        worst = ", ".join(f"{o} {c:.2f}" for o, c in over.items())
        if self.completes:
            what = (
                "the emulator route's centre, completed with the held-out runs' mean part off "
                f"the output basis, still misses the {self.runs} held-out runs by {worst} x the "
                f"noise SD on the {self.window} window (each run against the others' mean "
                "part: that part varies over the posterior)"
            )
            fix = "or raise [predict] check_runs"
        else:
            what = (
                "the emulator route's centre leaves out the runs' part off the output basis: it "
                f"misses the {self.runs} held-out runs by {worst} x the noise SD on the "
                f"{self.window} window (its bands hold that part)"
            )
            fix = (
                "or raise [predict] check_runs"
                if self.skipped
                else "or set [predict] off_basis = 'check_runs'"
            )
        return (
            f"{what}; its RMSE and CV(RMSE) are worse than the simulator route's would be; "
            "for Guideline 14 figures set [predict] method = 'simulator' (or raise [emulator] "
            f"pca_variance, {fix})"
        )


def check_draws(n_route: int, n_check: int, total: int) -> np.ndarray:
    """Indices (into the simulator route's thinned draws) of the held-out runs."""
    have = min(n_route, total)
    return np.unique(np.linspace(0, have - 1, min(n_check, have)).astype(int))


def check_route(ctx: Context, em: EmulatorResult, posterior: Posterior) -> RouteCheck:
    """Run the held-out check of ``method = "auto"`` (module docstring) and choose."""
    section = ctx.study.predict
    theta, _, pick = thin_draws(posterior, section.runs)  # the simulator route's draws
    sub = check_draws(section.runs, section.check_runs, len(pick))
    theta, pick = theta[sub], pick[sub]
    sims = simulate(ctx, Design.from_values(ctx.priors, theta), need=1)
    names = list(em.emulator.outputs.names)
    runs = level_values(ctx, {o: sims.outputs[o] for o in names}, "simulated")
    assembled = em.assembled
    layout = assembled.layout
    parts = predicted_parts(assembled)
    x, starts, begin = parts[-1]
    window = "test" if len(parts) > 1 else "train"
    emulator = emulator_with_test_window(em.emulator, assembled)
    ok = theta[sims.indices]
    lam = posterior.lam_stars.reshape(-1, len(names))[pick[sims.indices]]
    mean, _ = period_moments(emulator, ok, lam, x, None, np.zeros(emulator.outputs.sd.shape))
    noise = {o: float(np.median(v)) for o, v in posterior.noise_sd().items()}
    obs = assembled.observations
    order = [o.name for o in obs.outputs]
    completing = section.off_basis == "check_runs" and len(ok) >= 2
    if completing:
        # the unit of every figure: the noise the completed band uses, estimated again
        # from the runs (lambda* also holds the part off the basis the centre now has)
        again = simulator_noise(
            assembled, runs, posterior, pick[sims.indices], section.noise, em.emulator
        )
        noise = {
            o.name: float(
                np.median(
                    assembled.outputs.standardisations[q].sd[:, None] / np.sqrt(again[None, :, q])
                )
            )
            for q, o in enumerate(obs.outputs)
        }
    ratio: dict[str, float] = {}
    centre: dict[str, float] = {}
    completed: dict[str, float] = {}
    off_basis: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, sl in emulator.outputs.slices.items():
        series = np.full((len(ok), layout.n_total), np.nan)
        place_periods(layout, starts, mean[:, sl], series, begin)
        # the runs' part on the output basis: the emulator predicts the basis weights,
        # and its band holds the out-of-basis part apart (lambda* and the test window's
        # excess), so only the weights' error is the emulator's own; on every predicted
        # part (training periods and test window), for the centre's completion
        q = order.index(name)
        st, ko = assembled.outputs.standardisations[q], obs.block(q)[0]
        on_basis = np.full_like(series, np.nan)
        whole = np.full_like(series, np.nan)
        for r in range(len(ok)):
            every = np.asarray(runs[name][r], dtype=float)
            for _, part_starts, part_begin in parts:
                run = every[part_starts[None, :] + np.arange(layout.period)[:, None]]
                y = (run - st.mean[:, None]) / st.sd[:, None]
                fitted = st.mean[:, None] + st.sd[:, None] * (ko @ obs.weights_of(q, y).T)
                place_periods(layout, part_starts, fitted, on_basis[r], part_begin)
                place_periods(layout, part_starts, run, whole[r], part_begin)
        sd = noise.get(name, float("nan"))
        known = name in noise
        # series is NaN off the checked window, so these compare it there only
        ratio[name] = _rms(series - on_basis) / sd if known else float("inf")
        centre[name] = _rms(series - whole) / sd if known else float("inf")
        part = whole - on_basis  # (runs, n_total): the runs' part off the output basis
        if completing:
            # the mean part, and the variance of one more run's part about it
            spread = part.var(axis=0, ddof=1) * (1.0 + 1.0 / len(ok))
            off_basis[name] = (part.mean(axis=0), spread)
            # each run's centre completed with the other runs' mean part: held out
            others = (part.sum(axis=0)[None] - part) / (len(ok) - 1)
            completed[name] = _rms(series + others - whole) / sd if known else float("inf")
    good = len(ok) > 0 and all(r <= section.check_tolerance for r in ratio.values())
    return RouteCheck(
        "emulator" if good else "simulator",
        ratio,
        len(ok),
        window,
        section.check_tolerance,
        centre,
        completed,
        off_basis,
        skipped=section.off_basis == "check_runs" and not completing,
    )


def _rms(diff: np.ndarray) -> float:
    """Root mean square over the finite entries (``inf`` where there are none)."""
    used = np.isfinite(diff)
    return float(np.sqrt(np.mean(diff[used] ** 2))) if used.any() else float("inf")
