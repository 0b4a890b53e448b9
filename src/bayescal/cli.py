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
