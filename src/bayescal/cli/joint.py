"""``bayescal joint``: finished studies of several records calibrated together."""

from __future__ import annotations

from pathlib import Path

import click
import pandas as pd

from bayescal.cli.main import user_errors

__all__ = ["joint", "joint_text"]


@click.command()
@click.argument("studies", nargs=-1, type=click.Path(path_type=Path))
@click.option(
    "--out",
    "-o",
    type=click.Path(path_type=Path),
    default=Path("joint"),
    show_default=True,
    help="Folder for posterior.nc, joint-summary.csv, joint.png and joint.md (and the chains' "
    "snapshots, from which a killed run resumes).",
)
@click.option(
    "--seed",
    type=int,
    default=None,
    help="Root seed of the chains [default: the first study's calibration seed].",
)
@click.option(
    "--chains-backend",
    type=click.Choice(["processes", "serial"]),
    default="processes",
    show_default=True,
    help="Run the chains in worker processes or one after another here.",
)
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or notes; the table only.")
@user_errors
def joint(
    studies: tuple[Path, ...], out: Path, seed: int | None, chains_backend: str, quiet: bool
) -> None:
    """Calibrate the records of several finished studies together.

    STUDIES are two or more study files or folders, each calibrated on its own
    record of the same building or construction (the co-heating and the
    free-float phase of a test box, two walls of one house). Each keeps what it
    built on its record: its simulator runs, basis, emulator and error model.
    Their likelihoods are multiplied, and the parameters they share (same
    name) get one posterior; a parameter only some studies calibrate is held
    at its value in the others. A shared parameter must have the same prior in
    every study, and no study may take its prior from another's posterior
    ([study] prior_from), which would count those data twice.

    The chains run as the studies' [calibration] sections say (the largest
    chains, burn-in and draws among them, joint moves if any study has them)
    and are extended while a diagnostic fails. Each study must be up to date
    with its file (its emulator and calibrate stages finished with the
    file's present settings). A study's difference-process phase
    ([discrepancy] enabled) is not part of the joint calibration. The derived
    quantities (U, R, [derived]) are the first study's, at the joint draws.

    Prints each parameter's mean and 95 % interval from each study alone and
    jointly, and WARNING lines first where the joint posterior lies outside
    what one record alone allows (the records disagree: a model error in one
    of them at least), leans on a prior bound, or a diagnostic failed. The
    intervals hold the parameters' uncertainty given every record's error
    model; they do not hold a model error the studies do not model.

    Writes posterior.nc, joint-summary.csv, joint.png and joint.md (the table with
    its warnings first, and the figure) into --out.
    """
    from bayescal.cli.progress import progress_options
    from bayescal.pipeline import Options
    from bayescal.pipeline.joint import joint as run_joint

    options = Options(chains_backend=chains_backend, **progress_options(quiet))
    result = run_joint(
        studies,
        out,
        options=options,
        seed=seed,
        say=(lambda _: None) if quiet else click.echo,
    )
    for line in result.warnings:
        click.echo(f"WARNING: {line}")
    click.echo(joint_text(result.summary, result.labels))
    click.echo(f"chains: {result.seconds:.1f} s; wrote {', '.join(str(f) for f in result.files)}")


def joint_text(summary: pd.DataFrame, labels: tuple[str, ...]) -> str:
    """The table of ``bayescal joint``: a row per parameter, a column per source."""
    from bayescal.report.joint import interval_cell  # matplotlib: not at start-up

    sources = [*labels, "joint"]
    header = ["parameter", "unit", *sources]
    rows = [header]
    for name, group in summary.groupby("parameter", sort=False):
        by = group.set_index("source")
        cells = [str(name), str(group["unit"].iloc[0])]
        cells += [interval_cell(by, s) if s in by.index else "-" for s in sources]
        rows.append(cells)
    widths = [max(len(row[k]) for row in rows) for k in range(len(header))]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows
    ]
    return "\n".join(["means [95 % intervals]", *lines])
