"""Command-line interface: ``bayescal COMMAND``.

Errors a user can cause (:class:`~bayescal.errors.BayescalError`) are printed
as one line ``error: ...`` on stderr with exit status 2; ``--debug`` shows the
traceback instead. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import functools
import sys
import traceback
from collections.abc import Callable
from datetime import tzinfo
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from bayescal import __version__
from bayescal.errors import BayescalError

if TYPE_CHECKING:
    import pandas as pd

F = TypeVar("F", bound=Callable[..., Any])
EXIT_USER_ERROR = 2
#: ``bayescal run --strict``: an MCMC diagnostic failed (results written all the same).
EXIT_DIAGNOSTICS = 3


def user_errors(command: F) -> F:
    """Decorate a command: a BayescalError becomes one stderr line and exit status 2."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except BayescalError as exc:
            ctx = click.get_current_context()
            if (ctx.find_root().obj or {}).get("debug"):
                traceback.print_exc(file=sys.stderr)
            else:
                click.echo(f"error: {exc.one_line()}", err=True)
            ctx.exit(EXIT_USER_ERROR)

    return wrapper  # type: ignore[return-value]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="bayescal")
@click.option("--debug", is_flag=True, help="Show tracebacks of errors.")
@click.pass_context
def main(ctx: click.Context, debug: bool) -> None:
    """Bayesian calibration of building-simulation models against measured data."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


STUDY = click.argument("study", type=click.Path(path_type=Path))


def simulation_options(command: F) -> F:
    """The options that say where simulations run: ``--jobs``, ``--backend``, ``--scheduler``."""
    for option in reversed(
        (
            click.option(
                "--jobs", "-j", type=click.IntRange(min=1), default=None, help="Simulation workers."
            ),
            click.option(
                "--backend",
                type=click.Choice(["serial", "processes", "dask"]),
                default=None,
                help="Simulation backend [default: the study's runner.backend].",
            ),
            click.option(
                "--scheduler", default=None, help="Dask scheduler address (implies --backend dask)."
            ),
        )
    ):
        command = option(command)
    return command


@main.command()
@STUDY
@user_errors
def validate(study: Path) -> None:
    """Check a study: its configuration and its measured data.

    STUDY is study.toml or the folder holding it.
    """
    from bayescal.cli.progress import budget_line, study_summary, time_lines
    from bayescal.config import load_study
    from bayescal.data import load_measured
    from bayescal.pipeline import check_budget
    from bayescal.pipeline.budget import estimate_time

    config = load_study(study)
    measured = load_measured(config)
    needs = check_budget(config, measured)
    click.echo(study_summary(config, measured))
    click.echo(budget_line(needs))
    click.echo("\n".join(time_lines(estimate_time(config, measured))))


def _parse_assignments(values: tuple[str, ...]) -> dict[str, float]:
    """``("k_cb=0.124", ...)`` -> ``{"k_cb": 0.124}``; a malformed one is a user error."""
    from bayescal.errors import ConfigError

    out: dict[str, float] = {}
    for item in values:
        name, sep, text = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name.strip()] = float(text)
        except ValueError:
            raise ConfigError(
                f"--set expects NAME=VALUE with a number, got {item!r}",
                hint="e.g. --set k_cb=0.124",
            ) from None
    return out


def _local_time(option: str, text: str | None, zone: tzinfo) -> pd.Timestamp | None:
    """The time ``--from``/``--to`` gives: a local time of the data's ``zone`` (unless it
    carries its own UTC offset), in which the hour that a daylight-saving change repeats
    or skips is refused by name; an empty text or ``NaT`` is not a time."""
    import pandas as pd

    from bayescal.clock import local_to_utc
    from bayescal.errors import ConfigError

    if text is None:
        return None
    bad = ConfigError(f"{option} {text!r} is not a date and time", hint="e.g. 2013-09-20T00:00")
    try:
        value = pd.Timestamp(text)
    except ValueError:
        raise bad from None
    if pd.isna(value):  # pandas reads "", "NaT" and "nat" as no time at all
        raise bad
    local_to_utc(value, zone, option)
    return value


@main.command()
@STUDY
@click.option(
    "--set",
    "assignments",
    multiple=True,
    metavar="NAME=VALUE",
    help="Parameter value replacing the nominal one (physical units); repeatable.",
)
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=None,
    help="Folder for simulation.csv and simulation.png [default: OUTPUT_DIR/simulate].",
)
@user_errors
def simulate(study: Path, assignments: tuple[str, ...], out: Path | None) -> None:
    """Run the simulator once on the measured boundary conditions and compare.

    Prints fit metrics on the training and test windows and writes the series
    (CSV) and a measured-vs-simulated figure (PNG).
    """
    from bayescal.cli.progress import metrics_text
    from bayescal.config import load_study
    from bayescal.errors import ConfigError
    from bayescal.pipeline.run import writing
    from bayescal.simulate import check_simulation, write_simulation

    config = load_study(study)
    folder = out if out is not None else config.study.output_dir / "simulate"
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{folder} exists and is not a folder", hint="give --out a folder")
    check = check_simulation(config, _parse_assignments(assignments))
    values = ", ".join(f"{k}={v:g}" for k, v in check.parameters.items())
    with writing(folder):  # a read-only folder, a full disk, a file in the way: one line
        files = write_simulation(check, folder, title=f"{config.study.name}: {values}")
    click.echo(f"simulated {config.study.name!r} at {values}")
    click.echo(metrics_text(check.train, check.test))
    click.echo(f"wrote {files['csv']}\nwrote {files['png']}")


@main.command()
@click.argument("example", required=False)
@click.argument("directory", required=False, type=click.Path(path_type=Path))
@click.option(
    "--force", is_flag=True, help="Copy into DIRECTORY even if it exists and is not empty."
)
@user_errors
def init(example: str | None, directory: Path | None, force: bool) -> None:
    """Copy the worked example EXAMPLE into DIRECTORY (a new study folder).

    Without arguments, lists the examples.
    """
    from bayescal import examples
    from bayescal.errors import OutputError

    names = examples.available()
    if example is None:
        click.echo("examples: " + ", ".join(names))
        return
    target = directory if directory is not None else Path(example)
    try:
        examples.copy_example(example, target, force=force)
    except OSError as exc:  # a read-only folder, a full disk, a file in the way
        raise OutputError(
            f"cannot copy the example into {target}: {exc.strerror or exc}",
            hint="choose a folder you can write",
        ) from exc
    click.echo(f"created {target}/study.toml from example {example!r}")
    click.echo(f"next: bayescal validate {target}   or   bayescal simulate {target}")


@main.command()
@STUDY
@click.option(
    "--from",
    "from_stage",
    type=click.Choice(
        ["design", "simulate", "emulator", "calibrate", "discrepancy", "predict", "report"]
    ),
    default=None,
    help="Run this stage and every later one again, even if up to date.",
)
@click.option(
    "--until",
    type=click.Choice(
        ["design", "simulate", "emulator", "calibrate", "discrepancy", "predict", "report"]
    ),
    default="report",
    show_default=True,
    help="Stop after this stage.",
)
@simulation_options
@click.option("--quiet", "-q", is_flag=True, help="No progress bars or notes; errors only.")
@click.option(
    "--strict",
    is_flag=True,
    help="Exit with status 3 when an MCMC diagnostic failed (R-hat > 1.01, bulk or tail "
    "ESS < 400, stuck chains, divergences) in the calibration or the difference process; "
    "the results are written all the same.",
)
@user_errors
def run(
    study: Path,
    from_stage: str | None,
    until: str,
    jobs: int | None,
    backend: str | None,
    scheduler: str | None,
    quiet: bool,
    strict: bool,
) -> None:
    """Calibrate: design, simulate, emulator, calibrate, discrepancy, predict, report.

    Every stage writes its results into the study's output folder; running
    again reuses stages whose inputs did not change and resumes interrupted
    simulations. A log is kept in OUTPUT_DIR/bayescal.log. Progress is drawn as
    bars on a terminal; redirected to a file (bayescal run STUDY > log 2>&1) it is
    plain lines: one when a stage starts, one every 10 s or so, one when it ends.
    """
    from bayescal.cli.progress import describe, progress_options
    from bayescal.config import load_study
    from bayescal.pipeline import Options
    from bayescal.pipeline import run as run_pipeline

    config = load_study(study)
    options = Options(backend=backend, jobs=jobs, scheduler=scheduler, **progress_options(quiet))
    res = run_pipeline(
        config,
        from_stage=from_stage,
        until=until,
        options=options,
        say=(lambda _: None) if quiet else click.echo,
    )
    if not quiet:
        click.echo(describe(res))
        if res.report is not None:
            click.echo(f"report: {res.report}")
    failed = res.diagnostic_warnings()
    if strict and failed:
        click.echo(
            f"error: {len(failed)} MCMC diagnostic(s) failed (--strict): {failed[0]}"
            + (f" (and {len(failed) - 1} more, see bayescal.log)" if len(failed) > 1 else "")
            + "; run longer chains ([calibration] / [discrepancy] burn and samples)",
            err=True,
        )
        raise SystemExit(EXIT_DIAGNOSTICS)


@main.command()
@STUDY
@click.option(
    "--data",
    "data",
    type=click.Path(path_type=Path),
    default=None,
    help="The new record: a data file in the study's format and column mapping (its "
    "boundary conditions required, its measured outputs optional) [default with "
    "--scenario: the study's own data file].",
)
@click.option(
    "--scenario",
    "scenario",
    type=click.Path(path_type=Path),
    default=None,
    help="A scenario file ([baseline], [scenarios.NAME] with simulator = {...} keys and "
    "set = {...} parameters): every scenario against the baseline at the same posterior "
    "draws, with the paired interval of each change.",
)
@click.option(
    "--as",
    "as_study",
    type=click.Path(path_type=Path),
    default=None,
    help="Another study of the same building in another set-up (its data mapping, simulator "
    "settings and outputs, e.g. the free-float phase of a box calibrated on co-heating): "
    "predict its record with this calibration's posterior; its outputs' bands hold their "
    "stated accuracy ([outputs.errors.NAME] sd) [default data: its own file].",
)
@click.option(
    "--from",
    "start",
    default=None,
    metavar="TIME",
    help="Predict from this instant of the file (local time of the data) [default: its start].",
)
@click.option(
    "--to",
    "end",
    default=None,
    metavar="TIME",
    help="Predict up to this instant, exclusive [default: the file's end].",
)
@click.option(
    "--set",
    "assignments",
    multiple=True,
    metavar="NAME=VALUE",
    help="Fix a calibrated parameter at VALUE (physical units, inside its prior) in every "
    "posterior draw; repeatable.",
)
@click.option(
    "--method",
    type=click.Choice(["simulator", "emulator"]),
    default=None,
    help="Model part of the prediction: the simulator re-run at posterior draws, or the "
    "emulator (refused where the new conditions lie outside its training range) "
    "[default: the study's predict.method, the simulator outside the range].",
)
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=None,
    help="Folder for the prediction [default: OUTPUT_DIR/predict-<file name>].",
)
@simulation_options
@click.option("--quiet", "-q", is_flag=True, help="No progress bars or notes; errors only.")
@user_errors
def predict(
    study: Path,
    data: Path | None,
    scenario: Path | None,
    as_study: Path | None,
    start: str | None,
    end: str | None,
    assignments: tuple[str, ...],
    method: str | None,
    out: Path | None,
    jobs: int | None,
    backend: str | None,
    scheduler: str | None,
    quiet: bool,
) -> None:
    """Predict a new record, or compare scenarios, with a finished calibration.

    The calibrated model is run on the boundary conditions of another data
    file of the same construction (another season, another house, the rest of
    a campaign) with the study's whole uncertainty: parameters, noise, the
    in-likelihood discrepancy kriged at the new conditions and, where the study
    estimated it, the difference process. Where the file holds measurements,
    prints and writes the same metrics as the study's test window (RMSE against
    the nominal model, band coverage with the range an honest band shows).
    Writes predictions.nc, predictions.csv (mean, 50 % and outer bands per
    output), metrics.csv, summary.md and a figure per output.
    """
    import dataclasses

    from bayescal.cli.progress import progress_options
    from bayescal.config import load_study
    from bayescal.errors import ConfigError
    from bayescal.pipeline import Options, load_results
    from bayescal.pipeline.newdata import predict_new, summary_lines, write_new_prediction
    from bayescal.pipeline.run import writing

    config = load_study(study)
    other = load_study(as_study) if as_study is not None else None
    zone = (other or config).data.zone  # --from/--to: local times of the data predicted
    window = {key: _local_time(key, text, zone) for key, text in (("--from", start), ("--to", end))}
    if data is None and scenario is None and as_study is None:
        raise ConfigError(
            "predict needs --data FILE, --scenario FILE or --as STUDY", hint="see --help"
        )
    if data is not None and not data.is_file():
        raise ConfigError(f"{data}: no such data file", hint="give --data an existing file")
    stem = (
        scenario.stem
        if scenario is not None
        else data.stem
        if data is not None
        else f"as-{Path(as_study or '').resolve().name}"
    )
    folder = out if out is not None else config.study.output_dir / f"predict-{stem}"
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{folder} exists and is not a folder", hint="give --out a folder")
    options = Options(backend=backend, jobs=jobs, scheduler=scheduler, **progress_options(quiet))
    if scenario is not None:
        from bayescal.pipeline.scenario import run_scenarios, scenario_lines, write_scenarios

        if assignments or method:
            raise ConfigError("--set and --method do not apply to --scenario", hint="use set = {}")
        results = load_results(config)
        result = run_scenarios(
            dataclasses.replace(
                results, context=dataclasses.replace(results.context, options=options)
            ),
            scenario,
            data=data,
            start=window.get("--from"),
            end=window.get("--to"),
            say=(lambda _: None) if quiet else click.echo,
        )
        with writing(folder):
            written = write_scenarios(result, folder)
        click.echo("\n".join(scenario_lines(result)))
        click.echo(f"wrote {folder} ({', '.join(p.name for p in written.values())})")
        return
    if as_study is not None:
        from bayescal.pipeline.newdata import predict_as

        if method is not None:
            raise ConfigError("--method does not apply to --as (the simulator is re-run)")
        assert other is not None
        pred = predict_as(
            load_results(config),
            other,
            data,
            start=window.get("--from"),
            end=window.get("--to"),
            fixed=_parse_assignments(assignments),
            options=options,
            say=(lambda _: None) if quiet else click.echo,
        )
    else:
        assert data is not None
        pred = predict_new(
            load_results(config),
            data,
            start=window.get("--from"),
            end=window.get("--to"),
            fixed=_parse_assignments(assignments),
            method=method,
            options=options,
            say=(lambda _: None) if quiet else click.echo,
        )
    with writing(folder):
        files = write_new_prediction(pred, folder)
    if not quiet:
        click.echo("\n".join(summary_lines(pred)))
    click.echo(f"wrote {folder} ({', '.join(p.name for p in files.values())})")


@main.command()
@STUDY
@click.option(
    "--data",
    type=click.Path(path_type=Path),
    default=None,
    help="The file holding the newly arrived data, in the study's format and mapping "
    "[default: the study's own data file, read to its end].",
)
@click.option(
    "--to",
    "end",
    default=None,
    metavar="TIME",
    help="Use the data up to this instant, exclusive (local time of the data) "
    "[default: the file's end].",
)
@click.option(
    "--warmup",
    default=None,
    metavar="all|study|DURATION",
    help="How much of the record before the new days is simulated, not compared: 'all' "
    "(from the first study's start: the state of one calibration on every day), 'study' "
    "(the study's warm-up) or a duration, a multiple of the data step and at least the "
    "study's warm-up [default: all; with --data or after an update from another file, "
    "study].",
)
@simulation_options
@click.option("--quiet", "-q", is_flag=True, help="No progress bars or notes; errors only.")
@user_errors
def update(
    study: Path,
    data: Path | None,
    end: str | None,
    warmup: str | None,
    jobs: int | None,
    backend: str | None,
    scheduler: str | None,
    quiet: bool,
) -> None:
    """Add newly arrived data to a finished calibration (a sequential calibration).

    Writes update-00K.toml beside the study file: the study's settings on the
    record from its test window (less --warmup) to the end of the data,
    with the previous posterior as the prior of its parameters ([study]
    prior_from), and runs it into OUTPUT_DIR/update-00K. Its simulator runs are
    made again (runs are tied to their boundary conditions; one line says why);
    its calibration chains start from draws of the previous posterior. Each
    update starts from the last finished one; a killed update resumes. Prints and writes
    OUTPUT_DIR/update-history.csv: how the intervals narrowed, update by update.
    """
    import pandas as pd

    from bayescal.cli.progress import progress_options
    from bayescal.clock import parse_duration
    from bayescal.config import load_study
    from bayescal.errors import ConfigError
    from bayescal.pipeline import Options
    from bayescal.pipeline.update import WARMUPS
    from bayescal.pipeline.update import update as run_update

    config = load_study(study)
    stop = _local_time("--to", end, config.data.zone)
    if data is not None and not data.is_file():
        raise ConfigError(f"{data}: no such data file", hint="give --data an existing file")
    span: str | pd.Timedelta | None = warmup
    if warmup is not None and warmup not in WARMUPS:
        try:
            span = parse_duration(warmup)
        except ValueError:
            span = None
        if span is None or span <= pd.Timedelta(0):
            raise ConfigError(
                f"--warmup {warmup!r} is neither 'all', 'study' nor a positive duration",
                hint="e.g. --warmup all, --warmup study or --warmup 7D",
            )
    options = Options(backend=backend, jobs=jobs, scheduler=scheduler, **progress_options(quiet))
    result = run_update(
        config,
        data=data,
        end=stop,
        options=options,
        say=(lambda _: None) if quiet else click.echo,
        warmup=span,
    )
    columns = [c for c in result.history.columns if c.endswith(("_mean", "_lower", "_upper"))]
    shown = result.history[["update", "last_training", "training_periods", *columns]]
    click.echo("posterior, update by update (95 % intervals):")
    click.echo(shown.to_string(index=False, float_format="{:.5g}".format))
    click.echo(f"wrote {result.study.path} and {result.files['history']}")


@main.command()
@STUDY
@click.option(
    "--apply",
    is_flag=True,
    help="Set screen = false on the proposed parameters and screen = true on the others in "
    "the study file (the old file is kept as study.toml.bak).",
)
@simulation_options
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or notes; errors only.")
@user_errors
def screen(
    study: Path,
    apply: bool,
    jobs: int | None,
    backend: str | None,
    scheduler: str | None,
    quiet: bool,
) -> None:
    """Rank the parameters by Morris or Sobol indices and propose those to calibrate.

    Screens every [parameters.<name>] (candidates with screen = true and the
    calibrated ones) on each calibrated output over the training periods, by
    Morris elementary effects or, with [screening] method = "sobol", by the
    Sobol indices of a GP fitted to a Latin hypercube of runs; writes
    OUTPUT_DIR/screening/ (screening.html, morris.csv or sobol.csv,
    proposal.json). Runs are cached with the design's, so a second screen
    reuses them.
    """
    from bayescal.cli.progress import progress_options, screening_text
    from bayescal.config import load_study
    from bayescal.pipeline import Options
    from bayescal.pipeline.screen import screen as run_screen

    config = load_study(study)
    options = Options(backend=backend, jobs=jobs, scheduler=scheduler, **progress_options(quiet))
    res = run_screen(
        config, options=options, apply=apply, say=(lambda _: None) if quiet else click.echo
    )
    if not quiet:
        click.echo(screening_text(res.indices, res.proposal))
    if apply:
        changed = ", ".join(res.applied) or "none (already as proposed)"
        click.echo(f"updated screen flags in {config.path}: {changed}")
    click.echo(f"screening: {res.page}")


@main.command()
@STUDY
@user_errors
def show(study: Path) -> None:
    """Summarise a calibration: posterior, diagnostics, metrics (what has run so far).

    For a built-in wall with surface boundaries and daily periods, also the in-situ U
    of the ISO 9869-1 average method on the training days.
    """
    from bayescal.cli.insitu import iso9869_line
    from bayescal.cli.progress import describe
    from bayescal.config import load_study
    from bayescal.pipeline import load_results

    res = load_results(load_study(study))
    click.echo(describe(res))
    if (line := iso9869_line(res.context.study, res.context.measured)) is not None:
        click.echo(line)


@main.command()
@STUDY
@user_errors
def report(study: Path) -> None:
    """(Re)write the HTML report of a finished calibration."""
    from bayescal.config import load_study
    from bayescal.pipeline import load_results, write_study_report
    from bayescal.pipeline.run import writing
    from bayescal.store.folder import OutputLock

    results = load_results(load_study(study))
    out = results.context.out
    with writing(out), OutputLock(out, command="report"):
        path = write_study_report(results)
    click.echo(f"report: {path}")


@main.command()
@click.argument("studies", nargs=-1, type=click.Path(path_type=Path))
@click.option(
    "--output",
    "-o",
    type=click.Path(path_type=Path),
    default=Path("compare"),
    show_default=True,
    help="Folder for compare.csv, compare-periods.csv, compare.png and compare.md.",
)
@click.option(
    "--max-refits",
    type=click.IntRange(min=0),
    default=5,
    show_default=True,
    help="Exact refits per study at most, for periods whose Pareto k exceeds 0.7 "
    "(worst first); each runs the study's [calibration] chains again, without the period.",
)
@click.option(
    "--draws",
    type=click.IntRange(min=10),
    default=250,
    show_default=True,
    help="Posterior draws per chain used for the scores (thinned evenly).",
)
@click.option(
    "--catalogue/--no-catalogue",
    default=True,
    show_default=True,
    help="Also rank the catalogue model: every calibrated parameter at its nominal value, "
    "the error model fitted on the same emulator, one row per distinct error model; a "
    "WARNING line says when calibration does not beat it by more than one SE.",
)
@click.option(
    "--on",
    "on",
    multiple=True,
    metavar="OUTPUT",
    help="Score only this calibrated output (repeat for several); each must be "
    "calibrated by every study. Default: the outputs every study calibrates, so that "
    "variants calibrating different outputs are ranked on those they share.",
)
@click.option(
    "--held-out/--no-held-out",
    default=True,
    show_default=True,
    help="Also score the held-out sensors ([outputs] held_out) that every study holds "
    "out, on the training periods: each study's simulator at [predict] runs posterior "
    "draws (from the run cache where its predict stage has run) and the catalogue's "
    "nominal run, with the sensors' stated accuracy; a WARNING line says when the "
    "catalogue values predict one as well as the calibration.",
)
@simulation_options
@click.option("--quiet", "-q", is_flag=True, help="No progress bars or notes; the table only.")
@user_errors
def compare(
    studies: tuple[Path, ...],
    output: Path,
    max_refits: int,
    draws: int,
    catalogue: bool,
    on: tuple[str, ...],
    held_out: bool,
    jobs: int | None,
    backend: str | None,
    scheduler: str | None,
    quiet: bool,
) -> None:
    """Rank variants of a study by leave-one-period-out cross-validation.

    STUDIES are study files or folders: variants of one calibration
    (parameter sets, priors, error models, discrepancy on or off) on the same
    measured data, two or more, or one to rank against its catalogue model.
    Each is run up to its calibrate stage (or its finished stages are
    reused); then every training period is left out in
    turn and the measurements of that period are scored by their log density
    under the calibration on the others (PSIS, with exact refits where the
    Pareto k exceeds 0.7). The variants are ranked by the sum, the ELPD, with
    the difference to the best and its standard error. Beside them, the share
    of the training samples inside the 95 % and 50 % bands of their period
    left out, with its standard error over the periods: how the bands of a new
    period hold, before the test window is read. The ELPD ranks; the bands
    check, and a note says where one misses its rate by more than two SE or a
    period is predicted confidently wrong. Only the training periods are read:
    the test window is left for the final metrics of the variant chosen.

    Variants may calibrate different outputs (the inside heat flux alone, or
    the flux and a temperature inside the wall): they are then scored on the
    outputs that all of them calibrate (or those named by --on), each training
    period left out whole, so that a second sensor counts by what it teaches
    the calibration about the shared one.

    Before it starts it prints an order of magnitude of its cost (each
    variant's emulator and calibration from its sizes, and up to --max-refits
    refits of a calibration each), then a line as each variant starts.

    The catalogue model is ranked too unless --no-catalogue: every calibrated
    parameter held at its nominal value of the study file, the error model the
    study states (noise precisions, AR(1) coefficients, discrepancy variances)
    fitted with the same chains on the same emulator, and scored the same way,
    one row per distinct error model among the variants (on the first such
    variant's emulator). Where it ranks above the best calibrated variant of its
    error model, or less than one SE of the paired difference below it, a
    WARNING line says that calibration does not improve on the catalogue values
    on the left-out periods: the parameters absorb model error.

    Held-out sensors that every study holds out ([outputs] held_out) are
    scored too, unless --no-held-out: on the training periods, by the log
    density of their samples under each study's simulator at posterior draws
    (the catalogue's nominal run) with the sensor's stated accuracy, the RMSE
    and the share inside the 95 % and 50 % bands. A WARNING line says where the
    catalogue values predict a held-out sensor as well as the best calibrated
    study or better: the parameters absorb model error.

    Writes compare.csv (the ranking), compare-periods.csv (every period of
    every variant), compare-held-out.csv (where sensors are held out),
    compare.png and compare.md into --output; each study keeps
    its scores in OUTPUT_DIR/leave-period-out.npz for the next comparison.
    """
    from bayescal.cli.progress import comparison_text, progress_options
    from bayescal.pipeline import Options
    from bayescal.pipeline.compare import compare as compare_studies

    options = Options(backend=backend, jobs=jobs, scheduler=scheduler, **progress_options(quiet))
    result = compare_studies(
        studies,
        output=output,
        options=options,
        max_refits=max_refits,
        draws_per_chain=draws,
        say=(lambda _: None) if quiet else click.echo,
        catalogue=catalogue,
        on=on,
        held_out=held_out,
    )
    click.echo(
        comparison_text(result.table, result.notes, result.files, result.warnings, result.held_out)
    )
