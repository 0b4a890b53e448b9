"""All terminal text of the command line: summaries, tables and progress bars.

* :func:`study_summary` -- what ``bayescal validate`` prints;
* :func:`metrics_text` -- the metrics table of ``bayescal simulate``;
* :func:`describe` -- what ``bayescal run`` and ``bayescal show`` print;
* :func:`comparison_text` -- the ranking ``bayescal compare`` prints;
* :func:`screening_text` -- the Morris or Sobol ranks and proposal of ``bayescal screen``;
* :func:`progress_options` -- the progress of the simulations and the MCMC
  stages, as :class:`bayescal.pipeline.Options` takes them: tqdm bars on a
  terminal, a few plain lines per stage (:class:`LineProgress`) in a log.

The metric columns of every table come from :func:`bayescal.metrics.metric_columns`.
"""

from __future__ import annotations

import contextlib
import functools
import sys
from collections.abc import Callable, Mapping, Sequence
from time import monotonic
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from bayescal.metrics import KEY_COLUMNS, Metrics, band_notes, metric_columns
from bayescal.runner import Progress

if TYPE_CHECKING:
    from bayescal.pipeline import Results
    from bayescal.screening import MorrisIndices, Proposal, SobolIndices

__all__ = [
    "LineProgress",
    "budget_line",
    "comparison_text",
    "describe",
    "is_terminal",
    "mcmc_bar",
    "metrics_text",
    "progress_options",
    "screening_text",
    "study_summary",
    "time_lines",
]

Tick = Callable[[int], None]
#: Without a terminal, a stage's progress is a line at its start, one at most every
#: this many seconds (less often as the stage goes on: LineProgress), one at its end. [s]
LINE_INTERVAL = 10.0
#: Under the metrics of ``bayescal show``: what the test window was used for.
TEST_WINDOW_NOTE = (
    "The test window is read only for these final metrics; parameters, priors and error "
    "models are chosen on the training periods (bayescal compare)."
)


def study_summary(study: Any, measured: Any) -> str:
    """A short plain-text summary of a validated study and its data."""
    from bayescal.data.align import format_duration

    lines = [f"study {study.study.name!r} ({study.path})", _simulator_line(study.simulator)]
    candidates = len(study.candidates)
    held = f", {candidates} screening candidates held at nominal" if candidates else ""
    lines.append(f"parameters ({len(study.parameters)}{held}):")
    for name, p in study.parameters.items():
        prior = p.prior
        shape = f", a={prior.a:g}, b={prior.b:g}" if prior.distribution == "beta" else ""
        mark = " (screen)" if p.screen else ""
        targets = ", ".join(p.targets[:2]) + (
            f" and {len(p.targets) - 2} more" if len(p.targets) > 2 else ""
        )
        lines.append(
            f"  {name}{mark} [{p.unit}]: nominal {p.nominal:g}, {prior.distribution}"
            f"({prior.lower:g}, {prior.upper:g}{shape}) -> {targets}"
        )
    step = study.data.step
    lay = measured.layout
    dropped = int(lay.dropped_starts.size)
    first = min([*lay.train_starts.tolist(), *lay.dropped_starts.tolist()])
    lines += [
        f"data: {study.data.file} ({study.data.format})",
        f"  boundary conditions: {', '.join(study.boundary_conditions) or 'none'}",
        f"  calibrated outputs: {', '.join(study.outputs.calibrate)}",
        f"clock: step {format_duration(step)}, {measured.times[0]} to {measured.times[-1]} UTC, "
        f"{measured.n} samples ({format_duration(measured.n * step)})",
        f"periods: warm-up {first} samples{_leftover(first, lay.warmup, step, study)}, "
        f"{lay.m_star} training periods of {lay.period} samples"
        + (f" ({dropped} more dropped: missing data)" if dropped else "")
        + f", test window {lay.test} samples",
    ]
    gaps = measured.gaps
    if not gaps:
        lines.append("gaps: none")
    else:
        filled = sum(g.interpolated for g in gaps)
        bridged = [g for g in gaps if g.bridged]
        lines.append(
            f"gaps: {len(gaps)} ({filled} interpolated, {len(gaps) - filled} left missing"
            + (f", {len(bridged)} of them in boundary conditions" if bridged else "")
            + ")"
        )
        zone = getattr(measured, "zone", None)
        lines += [f"  {g.describe(zone)}" for g in gaps[:20]]
        if len(gaps) > 20:
            lines.append(f"  ... and {len(gaps) - 20} more")
        if bridged:
            longest = format_duration(max(g.length for g in bridged))
            lines.append(
                "  boundary conditions are bridged linearly over their gaps for the simulator "
                "and the periods the gaps touch are dropped; data.max_gap_interpolate = "
                f"'{longest}' interpolates them instead and keeps the periods"
            )
    excluded = getattr(measured, "excluded", ())
    if excluded:
        lines.append(f"excluded (data.exclude): {len(excluded)} window(s)")
        lines += [f"  {window.describe()}" for window in excluded]
    return "\n".join(lines)


def _leftover(first: int, warmup: int, step: Any, study: Any = None) -> str:
    """`` (192 of [periods] warmup = 4D + 12 left before the first whole period: ...)``
    where the first period of the grid starts after the warm-up asked for (the samples
    between join the warm-up, :mod:`bayescal.periods`); ``""`` where it does not. With
    ``[periods] train_from`` (an update) the warm-up is the record before it."""
    from bayescal.data.align import format_duration

    train_from = getattr(getattr(study, "periods", None), "train_from", None)
    if train_from is not None and warmup * step > pd.Timedelta(study.periods.warmup):
        asked = f"the record before [periods] train_from = {train_from:%Y-%m-%dT%H:%M:%S}"
    else:
        asked = f"[periods] warmup = {format_duration(warmup * step)}"
    if first == warmup:
        return f" ({asked})" if train_from is not None else ""
    return (
        f" ({warmup} of {asked} + {first - warmup} "
        "left before the first whole period: the periods lie on a grid that ends where the "
        "test window's periods begin)"
    )


def budget_line(needs: Any) -> str:
    """``needs: about 21 MiB of memory, 12 MiB of disk (largest: simulations)``."""
    from bayescal.pipeline.budget import format_bytes

    memory = sum(need.memory for need in needs)
    disk = sum(need.disk for need in needs)
    largest = max(needs, key=lambda need: need.memory).what
    return (
        f"needs: about {format_bytes(memory)} of memory, {format_bytes(disk)} of disk "
        f"(largest: {largest}; limits: [runner] max_memory, max_disk)"
    )


def time_lines(times: Any) -> list[str]:
    """``time: about 30 s ...`` (:func:`bayescal.pipeline.budget.estimate_time`), and a
    ``warning: ...`` line naming the key to change where it runs over an hour."""
    from bayescal.pipeline.budget import format_seconds

    parts = ", ".join(f"{part.what} {format_seconds(part.seconds)}" for part in times.parts)
    runs = times.simulator_runs
    lines = [
        f"time: about {format_seconds(times.seconds)} for the emulator and the MCMC ({parts}; "
        "an order of magnitude from a per-sweep cost model timed on the wall example), "
        f"plus {runs} simulator run{'s' if runs != 1 else ''} not timed here "
        "(bayescal simulate runs one)"
    ]
    warning = times.warning()
    return [*lines, f"warning: {warning}"] if warning else lines


def _simulator_line(sim: Any) -> str:
    if sim.type == "wall":
        layers = ", ".join(f"{layer.name} {layer.thickness * 1000:g} mm" for layer in sim.layers)
        return (
            f"simulator: wall, {sim.boundary} boundaries, layers outside to inside: {layers}; "
            f"outputs {', '.join(sim.outputs)}"
        )
    if sim.type == "box":
        return f"simulator: box, {sim.mode}, outputs {', '.join(sim.output_names())}"
    return f"simulator: {sim.type}"


def metrics_text(train: Mapping[str, Metrics], test: Mapping[str, Metrics]) -> str:
    """Plain-text table of fit metrics per output and window (``bayescal simulate``)."""
    columns = metric_columns("simulate")
    wide = max([16, *(len(name) + 2 for name in (*train, *test))])
    head = f"{'output':<{wide}}{'window':<8}" + "".join(f"{c.label:>{c.width}}" for c in columns)
    rows = [head]
    for window, metrics in (("train", train), ("test", test)):
        for name, m in metrics.items():
            values = m.as_dict()
            cells = "".join(
                f"{values[c.name]:>{c.width}}"
                if c.kind == "count"
                else f"{values[c.name]:>{c.width}.{c.digits}g}"
                for c in columns
            )
            rows.append(f"{name:<{wide}}{window:<8}{cells}")
    return "\n".join(rows)


def _first_screen(res: Results) -> list[str]:
    """What ``describe`` says first: whether the calibration helped (the report's top box).

    The parameters leaning on a prior bound and the outputs whose calibrated
    prediction is worse than the nominal out of sample (loud), then one line per
    output: calibrated against nominal RMSE out of sample
    (:mod:`bayescal.report.trust`).
    """
    from bayescal.calibration.modelerror import ModelErrorSize, discrepancy_ratios
    from bayescal.report.trust import catalogue_verdicts, held_out_outputs, trust_warnings

    sizes: tuple[ModelErrorSize, ...] = ()
    if res.posterior is not None and res.emulator is not None:
        sizes = discrepancy_ratios(res.emulator.emulator, res.posterior)
    metrics = None
    held: tuple[str, ...] = ()
    if res.predictions is not None:
        metrics = res.predictions.metrics
        held = held_out_outputs(dict(res.predictions.dataset.attrs))
    disc = res.discrepancy.posterior if res.discrepancy is not None else None
    lines = [f"WARNING: {w}" for w in trust_warnings(res.posterior, disc, metrics, held, sizes)]
    if res.predictions is not None and (text := res.predictions.dataset.attrs.get("route_warning")):
        lines.append(f"WARNING: {text}")  # [predict] method = "auto": the route's centre
    if res.context.study.study.prior_from is not None:  # a sequential calibration
        from bayescal.pipeline.update import JOINT_NOTE

        lines.append(f"note: the prior is another study's posterior; {JOINT_NOTE}")
    if sizes:
        lines += ["", "model error (in-likelihood discrepancy against the noise):"]
        lines += [f"  {size.line()}" for size in sizes]
    if metrics is not None:
        lines += ["", "out of sample, calibrated against nominal (catalogue) parameters:"]
        lines += [f"  {v.line()}" for v in catalogue_verdicts(metrics, held)]
    return ["", *lines] if lines else []


def describe(res: Results) -> str:
    """A terminal summary: whether the calibration helped (first), posterior table,
    diagnostics, metrics, and what is not there yet."""
    first = _first_screen(res)
    lines = [f"study {res.context.study.study.name!r} -> {res.context.out}", *first]
    if res.posterior is not None:
        table = res.posterior.summary()
        held = res.context.held  # reuse_screening's screened-out inputs: not calibrated
        table = table.drop(index=[n for n in held if n in table.index])
        lines += ["", "posterior (physical units):", table.to_string(float_format="{:.5g}".format)]
        if held:
            values = ", ".join(f"{n} {v:.5g}" for n, v in held.items())
            lines.append(
                f"held at their nominal values, not calibrated (screened out; the emulator "
                f"keeps them as inputs for the reused screening runs): {values}"
            )
        sds = res.posterior.noise_sd()
        for o in res.posterior.noise:
            sd = sds[o.name].reshape(-1)
            low, high = np.percentile(sd, [2.5, 97.5])
            line = (
                f"measurement noise of {o.name} ({o.model}): SD {np.mean(sd):.4g} {o.unit} "
                f"[{low:.4g}, {high:.4g}]"
            )
            attrs = res.predictions.dataset.attrs if res.predictions is not None else {}
            if f"{o.name}_calibrated_noise_sd" in attrs:
                in_band = float(attrs[f"{o.name}_calibrated_noise_sd"])
                source = (
                    "the emulator's centre completed off the basis"
                    if attrs.get("off_basis")
                    else "the re-run simulator"
                )
                line += f"; in the bands (from {source}) {in_band:.4g} {o.unit}"
            lines.append(line)
        from bayescal.calibration.identifiability import identifiability

        ident = identifiability(res.posterior)
        lines += ["", "what the data fix (principal directions of the posterior vs the prior):"]
        lines += [f"  {line}" for line in ident.lines()]
        contraction = ", ".join(
            f"{n} {100 * c:.0f} %" for n, c in zip(ident.names, ident.contraction, strict=True)
        )
        lines.append(f"  prior-to-posterior contraction: {contraction}")
        if len(ident.names) > 1:
            import pandas as pd

            corr = pd.DataFrame(ident.correlation, index=ident.names, columns=ident.names)
            lines += ["  posterior correlation (log scale for positive parameters):"]
            text = corr.to_string(float_format="{:+.2f}".format)
            lines += [f"    {row}" for row in text.split("\n")]
        if res.posterior.warnings:
            lines += ["", "diagnostics: NOT all passed"]
            lines += [f"  warning: {w}" for w in res.posterior.warnings]
        else:
            lines += ["", "diagnostics: all passed (R-hat <= 1.01, bulk and tail ESS >= 400)"]
    if res.emulator is not None:
        logs = res.context.transforms
        for name, rmse in res.emulator.loo.rmse.items():
            scale = f", on the scale of log({name} + floor)" if name in logs else ""
            lines.append(
                f"emulator leave-one-run-out RMSE of {name}: {rmse:.4g} "
                f"(output SD {res.emulator.loo.output_sd[name]:.4g}){scale}"
            )
    if res.predictions is not None:
        m = res.predictions.metrics
        cols = [*KEY_COLUMNS, *(c.name for c in metric_columns("show"))]
        lines += [
            "",
            "metrics (max_abs_error is the paper's 'MAE'; CV(RMSE), NMBE in %; guideline14: "
            "CV(RMSE) <= 30 % and |NMBE| <= 10 %, ASHRAE Guideline 14 hourly):",
        ]
        cols = [c for c in cols if c in m.columns]  # older runs lack newer columns
        lines.append(m[cols].to_string(index=False, float_format="{:.4g}".format))
        from bayescal.report.answer import route_used  # matplotlib: not at import time

        attrs = dict(res.predictions.dataset.attrs)
        level = float(attrs.get("level", 0.95))
        if attrs.get("route"):  # predictions of an earlier bayescal do not record it
            lines.append(f"  bands from {route_used(attrs)}")
        lines += [f"  note: {n}" for n in band_notes(m, level=level)]
        lines.append(TEST_WINDOW_NOTE)
    if res.simulations is not None and res.simulations.failures:
        lines += ["", f"{len(res.simulations.failures)} failed run(s):"]
        lines += [f"  run {f.index}: {f.error_type}: {f.message}" for f in res.simulations.failures]
    loud = sum(line.startswith("WARNING: ") for line in first)
    if loud:
        lines += ["", f"{loud} warning(s) at the top of this summary (WARNING: ...)"]
    missing = res.missing()
    if missing:
        lines += [
            "",
            f"not run yet: {', '.join(missing)} "
            f"(`bayescal run {res.context.study.path}` runs them)",
        ]
    return "\n".join(lines)


def is_terminal(stream: Any) -> bool:
    """Whether ``stream`` is a terminal (a closed or odd stream counts as none)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def _duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``2 h 07 min``."""
    s = round(seconds)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class LineProgress:
    """Progress for a log file: plain lines, no ``\\r`` redraws.

    One line when the stage starts, one when it ends, and between them a line
    (done, share, elapsed, time left at the rate so far) every ``interval`` seconds
    for the first ``10 * interval`` seconds, then every tenth of the time elapsed:
    a stage of ten minutes writes about 30 lines, one of a day about 80.
    """

    def __init__(
        self,
        label: str,
        total: int,
        unit: str,
        stream: Any,
        interval: float = LINE_INTERVAL,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.label, self.total, self.unit = label, total, unit
        self.stream, self.interval = stream, interval
        self.clock = monotonic if clock is None else clock
        self.n = self.first = 0
        self.note = ""
        self.started = self.last = self.clock()
        self.closed = False
        self._write(f"{label}: started, {total} {unit}")

    def _write(self, text: str) -> None:
        with contextlib.suppress(OSError, ValueError):  # a closed or full stream
            self.stream.write(text + "\n")
            self.stream.flush()

    def start_at(self, n: int) -> None:
        """``n`` done before the first update (runs read from the cache): not in the rate."""
        self.n = self.first = n

    def update(self, n: int, note: str = "") -> None:
        """``n`` done so far (the total grows if ``n`` passes it); a line if one is due."""
        self.n, self.note = n, note
        self.total = max(self.total, n)
        now = self.clock()
        gap = max(self.interval, (now - self.started) / 10)
        if now - self.last >= gap and not self.closed:
            self.last = now
            self._write(self._status(now))

    def _status(self, now: float) -> str:
        elapsed = now - self.started
        share = f" ({100 * self.n / self.total:.0f} %)" if self.total else ""
        text = f"{self.label}: {self.n}/{self.total} {self.unit}{share}, {_duration(elapsed)}"
        rate = (self.n - self.first) / elapsed if elapsed > 0 else 0.0
        if rate > 0 and self.n < self.total:
            text += f", about {_duration((self.total - self.n) / rate)} left"
        return text + (f", {self.note}" if self.note else "")

    def close(self) -> None:
        """The last line: how many were done and how long it took."""
        if self.closed:
            return
        self.closed = True
        elapsed = self.clock() - self.started
        note = f", {self.note}" if self.note else ""
        self._write(
            f"{self.label}: finished {self.n}/{self.total} {self.unit} in {_duration(elapsed)}"
            + note
        )


def mcmc_bar(
    quiet: bool, stream: Any = None
) -> Callable[[str, int], tuple[Tick, Callable[[], None]]]:
    """Factory of MCMC progress: ``(label, total) -> (tick, close)``.

    A tqdm bar when ``stream`` (standard error by default) is a terminal, plain
    lines (:class:`LineProgress`) when it is not, nothing when ``quiet``.
    """

    def factory(label: str, total: int) -> tuple[Tick, Callable[[], None]]:
        out = sys.stderr if stream is None else stream
        if quiet:
            return (lambda done: None), (lambda: None)
        if not is_terminal(out):
            lines = LineProgress(label, total, "it", out)
            return lines.update, lines.close
        from tqdm.auto import tqdm

        bar = tqdm(total=total, desc=label, unit="it", mininterval=0.5, file=out)

        def tick(done: int) -> None:
            # A phase that extends its chains past the planned total (the difference
            # process, until it converges) grows the bar instead of sitting at 100 %.
            if done > (bar.total or 0):
                bar.total = done
                bar.refresh()
            bar.update(max(0, done - bar.n))

        return tick, bar.close

    return factory


def progress_options(quiet: bool, stream: Any = None) -> dict[str, Any]:
    """The progress callbacks of :class:`bayescal.pipeline.Options`: one for the
    simulations and one per MCMC stage (none when ``quiet``); bars on a terminal,
    plain lines otherwise (``stream``: standard error by default)."""
    return {
        "progress": None if quiet else functools.partial(simulation_bar, stream=stream),
        "mcmc_progress": mcmc_bar(quiet, stream),
    }


def simulation_bar(
    total: int, desc: str = "simulations", stream: Any = None
) -> tuple[Progress, Callable[[], None]]:
    """A progress callback that draws a tqdm bar (with ETA), and the function that closes it.

    Parameters
    ----------
    total
        Number of runs in the design.
    desc
        Label of the bar.
    stream
        Where it goes (standard error by default): a bar on a terminal, plain
        lines (:class:`LineProgress`) otherwise.

    Returns
    -------
    tuple
        ``(progress, close)``: pass ``progress`` to :func:`bayescal.runner.run_design`, call
        ``close()`` afterwards. Runs loaded from the cache on the first call do
        not count towards the rate, so the ETA reflects real runs.
    """
    out = sys.stderr if stream is None else stream
    state = {"first": True}
    if not is_terminal(out):
        lines = LineProgress(desc, total, "runs", out)

        def progress_lines(done: int, failed: int, total: int) -> None:
            if state["first"]:
                lines.start_at(done + failed)
                state["first"] = False
            lines.update(done + failed, f"{failed} failed" if failed else "")

        return progress_lines, lines.close

    from tqdm.auto import tqdm

    bar = tqdm(total=total, desc=desc, unit="run", file=out)

    def progress(done: int, failed: int, total: int) -> None:
        count = done + failed
        if state["first"]:
            bar.initial = bar.n = count
            bar.last_print_n = count
            state["first"] = False
        else:
            bar.update(count - bar.n)
        bar.set_postfix(failed=failed, refresh=True)

    return progress, bar.close


def _band(row: Any, column: str) -> str:
    """``0.970±0.007``: a left-out band's coverage and its SE (blank where absent)."""
    value = float(row.get(column, float("nan")))
    se = float(row.get(f"{column}_se", float("nan")))
    if value != value:
        return "–"
    return f"{value:.3f}±{se:.3f}" if se == se else f"{value:.3f}"


def comparison_text(
    table: Any,
    notes: Sequence[str],
    files: Mapping[str, Any],
    warnings: Sequence[str] = (),
    held_out: Any = None,
) -> str:
    """The ranking of ``bayescal compare``: loud warnings, table, verdicts, the held-out
    sensors' scores, notes and the files written."""
    from bayescal.report.compare import (
        SMALL_DIFFERENCE,
        diagnostics_mark,
        failed_diagnostics,
        model_mark,
        verdict,
    )

    width = max(20, 1 + max(len(str(v)) for v in table["variant"]))
    head = (
        f"{'rank':>4}  {'variant':<{width}}{'ELPD':>11}{'SE':>8}{'diff':>10}{'SE diff':>9}"
        f"{'p_loo':>8}{'k>0.7':>7}{'refits':>7}{'band95':>14}{'band50':>14}  MCMC"
    )
    lines = [f"WARNING: {w}" for w in warnings]
    scored = sorted(set(table["scored_on"])) if "scored_on" in table else []
    on = f" of {', '.join(str(o) for o in scored)}" if len(scored) == 1 else ""
    lines += [
        f"leave-one-period-out ELPD over {int(table['periods'].iloc[0])} training periods "
        f"(log density of the measurements{on} in their units, nats; higher is better):",
        head,
    ]
    for _, r in table.iterrows():
        lines.append(
            f"{int(r['rank']):>4}  {r['variant']!s:<{width}}{r['elpd']:>11.1f}{r['se']:>8.1f}"
            f"{r['elpd_diff']:>10.1f}{r['se_diff']:>9.1f}{r['p_loo']:>8.1f}"
            f"{int(r['k_high']):>7}{int(r['refits']):>7}"
            f"{_band(r, 'loo_band95'):>14}{_band(r, 'loo_band50'):>14}"
            f"  {'FAILED !' if failed_diagnostics(r) else 'ok'}"
        )
    lines.append("")
    lines += [
        f"{r['variant']}: {verdict(r['elpd_diff'], r['se_diff'])}{model_mark(r)}"
        f"{diagnostics_mark(r)}"
        for _, r in table.iterrows()
    ]
    lines.append(
        f"(a difference counts when it exceeds {SMALL_DIFFERENCE:g} nats and twice its SE; "
        "band95/band50: share of the training samples inside the 95 %/50 % band of their "
        "period left out, ± its SE over the periods; the ranking is by ELPD, the bands are "
        "a check; MCMC: the calibration's R-hat and ESS checks, FAILED: its rank is not "
        "reliable; the test window was not read)"
    )
    if held_out is not None and len(held_out):
        lines += ["", *_held_out_lines(held_out, width)]
    lines += [f"note: {n}" for n in notes]
    lines += [f"wrote {path}" for path in files.values()]
    return "\n".join(lines)


def screening_text(indices: Sequence[MorrisIndices | SobolIndices], proposal: Proposal) -> str:
    """The ranks of each output (Morris mu* with its 95 % interval, or Sobol ST and S1 with
    theirs and the GP's leave-one-out Q2) and the proposal."""
    from bayescal.screening import Q2_WARN, SobolIndices

    lines = []
    for ix in indices:
        if isinstance(ix, SobolIndices):
            lines.append(
                f"{ix.output}: Sobol ST and S1 [95 %] through a GP of {ix.runs} runs "
                f"(leave-one-out Q2 {ix.q2:.3f})"
            )
            low, high = ix.st_lower, ix.st_upper
            for j in np.argsort(-ix.st, kind="stable"):
                lines.append(
                    f"  {int(ix.ranks[j]):3d}  {ix.names[j]:<24s} ST {ix.st[j]:6.3f} "
                    f"[{low[j]:.3f}, {high[j]:.3f}]  S1 {ix.s1[j]:6.3f}"
                )
            if not ix.reliable:
                lines.append(
                    f"  warning: Q2 < {Q2_WARN:g}: the ranking is unreliable; raise "
                    "[screening] runs or use method = 'morris'"
                )
            continue
        lines.append(f"{ix.output}: mu* [per prior range] ({ix.trajectories} trajectories)")
        for j in np.argsort(-ix.mu_star, kind="stable"):
            lines.append(
                f"  {int(ix.ranks[j]):3d}  {ix.names[j]:<24s} {ix.mu_star[j]:11.4g} "
                f"± {ix.mu_star_conf[j]:<10.3g} sigma {ix.sigma[j]:.3g}"
            )
    cap = "" if proposal.max_parameters is None else f", at most {proposal.max_parameters}"
    lines.append(
        f"proposed ({proposal.measure} >= {proposal.threshold:g} × the largest for an "
        f"output{cap}): " + (", ".join(proposal.selected) or "none")
    )
    return "\n".join(lines)


_MCMC_MARK = {"failed": "FAILED !", "none": "-"}


def _held_out_lines(held_out: Any, width: int) -> list[str]:
    """The held-out sensors' scores of ``bayescal compare``, one block per sensor."""
    lines = []
    for name, rows in held_out.groupby("output", sort=False):
        lines.append(
            f"held-out sensor {name} (never calibrated on; training periods, stated SD "
            f"{rows['sd'].iloc[0]:.3g}; log density in nats, higher is better):"
        )
        lines.append(
            f"{'rank':>4}  {'variant':<{width}}{'log dens.':>11}{'SE':>8}{'diff':>10}"
            f"{'SE diff':>9}{'RMSE':>10}{'band95':>14}{'band50':>14}  MCMC"
        )
        for _, r in rows.iterrows():
            b95 = f"{r['band95']:.3f}±{r['band95_se']:.3f}"
            b50 = f"{r['band50']:.3f}±{r['band50_se']:.3f}"
            lines.append(
                f"{int(r['rank']):>4}  {r['variant']!s:<{width}}{r['lpd']:>11.1f}{r['se']:>8.1f}"
                f"{r['lpd_diff']:>10.1f}{r['se_diff']:>9.1f}{r['rmse']:>10.3g}{b95:>14}{b50:>14}"
                f"  {_MCMC_MARK.get(r['diagnostics'], 'ok')}"
            )
    lines.append(
        "(each variant's simulator at posterior draws, the catalogue's nominal run, with "
        "the sensor's stated accuracy; a calibration that predicts a sensor it never saw "
        "worse than the catalogue values has put model error into its parameters)"
    )
    return lines
