"""The user guide builds with warnings as errors, and its generated pages are current."""

import subprocess
import sys
from pathlib import Path

import click
import pytest

from bayescal.cli import main
from bayescal.cli.reference import cli_reference_markdown

ROOT = Path(__file__).resolve().parents[1]
CLI_DOC = ROOT / "docs" / "cli.md"


def test_committed_cli_reference_is_current() -> None:
    assert CLI_DOC.read_text(encoding="utf-8") == cli_reference_markdown(), (
        "docs/cli.md is stale: run `python -m bayescal.cli.reference > docs/cli.md`"
    )


def test_cli_reference_documents_every_command_and_option() -> None:
    text = cli_reference_markdown()
    root = click.Context(main, info_name="bayescal")
    for name, command in main.commands.items():
        assert f"### `bayescal {name}`" in text
        ctx = click.Context(command, info_name=name, parent=root)
        for param in command.get_params(ctx):
            if isinstance(param, click.Option):
                for opt in param.opts:
                    assert f"`{opt}`" in text, f"{opt} of {name} missing"
            else:
                assert f"| `{param.human_readable_name}` |" in text
    assert "0x" not in text  # no object addresses: the text is deterministic


def test_cli_reference_describes_types_and_defaults() -> None:
    text = cli_reference_markdown()
    run = text[text.index("### `bayescal run`") :]
    assert "| `--until` | `design` \\| `simulate`" in run
    assert "| `report` |" in run  # the default of --until
    assert "| `--jobs`, `-j` | integer ≥ 1 |" in run
    assert "| `--quiet`, `-q` | flag |" in run


def test_committed_images_are_small() -> None:
    images = sorted((ROOT / "docs").rglob("*.png"))
    assert images, "the tutorial's figures are missing from docs/img"
    for image in images:
        # the repository keeps only small figures; 150 kB is the agreed ceiling
        assert image.stat().st_size < 150_000, f"{image.name} is {image.stat().st_size} bytes"


@pytest.mark.slow
def test_site_builds_strictly(tmp_path: Path) -> None:
    """``mkdocs build --strict``: every warning (broken link, unknown API object, bad
    docstring) fails the build."""
    site = tmp_path / "site"
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "-d", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    for page in ("index.html", "tutorial.html", "cli.html", "study-file.html", "method.html"):
        assert (site / page).is_file(), page
    api = (site / "api" / "emulator.html").read_text(encoding="utf-8")
    assert 'id="bayescal.emulator.training.train"' in api  # mkdocstrings rendered the docstrings
    tutorial = (site / "tutorial.html").read_text(encoding="utf-8")
    assert "img/tutorial-fit.png" in tutorial
    assert (site / "img" / "tutorial-fit.png").is_file()
