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
from pathlib import Path
from typing import Any, TypeVar

import click

from bayescal import __version__
from bayescal.errors import BayescalError

F = TypeVar("F", bound=Callable[..., Any])
EXIT_USER_ERROR = 2


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


@main.command()
@STUDY
@user_errors
def validate(study: Path) -> None:
    """Check a study: its configuration and its measured data.

    STUDY is study.toml or the folder holding it.
    """
    from bayescal.cli.progress import study_summary
    from bayescal.config import load_study
    from bayescal.data import load_measured

    config = load_study(study)
    measured = load_measured(config)
    click.echo(study_summary(config, measured))


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
    from bayescal.simulate import check_simulation, write_simulation

    config = load_study(study)
    folder = out if out is not None else config.study.output_dir / "simulate"
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{folder} exists and is not a folder", hint="give --out a folder")
    check = check_simulation(config, _parse_assignments(assignments))
    values = ", ".join(f"{k}={v:g}" for k, v in check.parameters.items())
    try:
        files = write_simulation(check, folder, title=f"{config.study.name}: {values}")
    except OSError as exc:  # a read-only folder, a full disk, a file in the way
        raise ConfigError(f"cannot write into {folder}: {exc.strerror or exc}") from None
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

    names = examples.available()
    if example is None:
        click.echo("examples: " + ", ".join(names))
        return
    target = directory if directory is not None else Path(example)
    examples.copy_example(example, target, force=force)
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
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=None, help="Simulation workers.")
@click.option(
    "--backend",
    type=click.Choice(["serial", "processes", "dask"]),
    default=None,
    help="Simulation backend [default: the study's runner.backend].",
)
@click.option("--scheduler", default=None, help="Dask scheduler address (implies --backend dask).")
@click.option("--quiet", "-q", is_flag=True, help="No progress bars or notes; errors only.")
@user_errors
def run(
    study: Path,
    from_stage: str | None,
    until: str,
    jobs: int | None,
    backend: str | None,
    scheduler: str | None,
    quiet: bool,
) -> None:
    """Calibrate: design, simulate, emulator, calibrate, discrepancy, predict, report.

    Every stage writes its results into the study's output folder; running
    again reuses stages whose inputs did not change and resumes interrupted
    simulations. A log is kept in OUTPUT_DIR/bayescal.log.
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


@main.command()
@STUDY
@click.option(
    "--apply",
    is_flag=True,
    help="Set screen = false on the proposed parameters and screen = true on the others in "
    "the study file (the old file is kept as study.toml.bak).",
)
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=None, help="Simulation workers.")
@click.option(
    "--backend",
    type=click.Choice(["serial", "processes", "dask"]),
    default=None,
    help="Simulation backend [default: the study's runner.backend].",
)
@click.option("--scheduler", default=None, help="Dask scheduler address (implies --backend dask).")
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
    """Rank the parameters by Morris elementary effects and propose those to calibrate.

    Screens every [parameters.<name>] (candidates with screen = true and the
    calibrated ones) on each calibrated output over the training periods;
    writes OUTPUT_DIR/screening/ (screening.html, morris.csv, proposal.json).
    Runs are cached with the design's, so a second screen reuses them.
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
    """Summarise a calibration: posterior, diagnostics, metrics (what has run so far)."""
    from bayescal.cli.progress import describe
    from bayescal.config import load_study
    from bayescal.pipeline import load_results

    click.echo(describe(load_results(load_study(study))))


@main.command()
@STUDY
@user_errors
def report(study: Path) -> None:
    """(Re)write the HTML report of a finished calibration."""
    from bayescal.config import load_study
    from bayescal.pipeline import load_results, write_study_report

    path = write_study_report(load_results(load_study(study)))
    click.echo(f"report: {path}")
