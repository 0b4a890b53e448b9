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
    from bayescal.config import load_study
    from bayescal.data import load_measured

    config = load_study(study)
    measured = load_measured(config)
    click.echo(summary(config, measured))


def summary(study: Any, measured: Any) -> str:
    """A short plain-text summary of a validated study and its data."""
    from bayescal.data.align import format_duration

    lines = [f"study {study.study.name!r} ({study.path})", _simulator_line(study.simulator)]
    lines.append(f"parameters ({len(study.parameters)}):")
    for name, p in study.parameters.items():
        prior = p.prior
        shape = f", a={prior.a:g}, b={prior.b:g}" if prior.distribution == "beta" else ""
        lines.append(
            f"  {name} [{p.unit}]: nominal {p.nominal:g}, {prior.distribution}"
            f"({prior.lower:g}, {prior.upper:g}{shape}) -> {', '.join(p.targets)}"
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
        f"periods: warm-up {first} samples, {lay.m_star} training periods of {lay.period} "
        "samples"
        + (f" ({dropped} more dropped: missing outputs)" if dropped else "")
        + f", test window {lay.test} samples",
    ]
    gaps = measured.gaps
    if not gaps:
        lines.append("gaps: none")
    else:
        filled = sum(g.interpolated for g in gaps)
        lines.append(
            f"gaps: {len(gaps)} ({filled} interpolated, {len(gaps) - filled} left missing)"
        )
        lines += [f"  {g.describe()}" for g in gaps[:20]]
        if len(gaps) > 20:
            lines.append(f"  ... and {len(gaps) - 20} more")
    return "\n".join(lines)


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
    click.echo(metrics_table(check.train, check.test))
    click.echo(f"wrote {files['csv']}\nwrote {files['png']}")


def metrics_table(train: dict[str, Any], test: dict[str, Any]) -> str:
    """Plain-text table of fit metrics per output and window (``bayescal simulate``)."""
    from bayescal.metrics import metric_columns

    columns = metric_columns("simulate")
    head = f"{'output':<16}{'window':<8}" + "".join(f"{c.label:>{c.width}}" for c in columns)
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
            rows.append(f"{name:<16}{window:<8}{cells}")
    return "\n".join(rows)


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
    copy_example(example, target, force=force)
    click.echo(f"created {target}/study.toml from example {example!r}")
    click.echo(f"next: bayescal validate {target}   or   bayescal simulate {target}")


def copy_example(example: str, target: Path, *, force: bool = False) -> Path:
    """Copy a shipped example study folder to ``target``."""
    import shutil

    from bayescal import examples
    from bayescal.errors import ConfigError

    names = examples.available()
    if example not in names:
        raise ConfigError(f"no example {example!r}", hint=f"choose one of {', '.join(names)}")
    if target.exists() and any(target.iterdir()) and not force:
        raise ConfigError(
            f"{target} exists and is not empty", hint="choose a new folder or pass --force"
        )
    shutil.copytree(
        examples.path(example),
        target,
        dirs_exist_ok=True,
        ignore=shutil.ignore_patterns("out", "__pycache__"),
    )
    return target


def _mcmc_bar(quiet: bool) -> Any:
    """Factory of tqdm bars for MCMC progress: ``(label, total) -> (tick, close)``."""
    from tqdm.auto import tqdm

    def factory(label: str, total: int) -> tuple[Callable[[int], None], Callable[[], None]]:
        bar = tqdm(total=total, desc=label, unit="it", disable=quiet, mininterval=0.5)

        def tick(done: int) -> None:
            bar.update(max(0, min(done, total) - bar.n))

        return tick, bar.close

    return factory


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
    from bayescal.config import load_study
    from bayescal.pipeline import Options, describe
    from bayescal.pipeline import run as run_pipeline
    from bayescal.runner import tqdm_progress

    config = load_study(study)
    options = Options(
        backend=backend,
        jobs=jobs,
        scheduler=scheduler,
        progress=None if quiet else tqdm_progress,
        mcmc_progress=_mcmc_bar(quiet),
    )
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
@user_errors
def show(study: Path) -> None:
    """Summarise a finished calibration: posterior, diagnostics, metrics."""
    from bayescal.config import load_study
    from bayescal.pipeline import describe, load_results

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
