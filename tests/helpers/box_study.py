"""The test-box examples at reduced size, shared by the tests that run them end to end."""

from __future__ import annotations

from pathlib import Path

from bayescal.examples import copy_example

#: Reduced sizes: 16 runs (4 per parameter) and short chains.
REDUCED = """
[design]
runs = 16

[emulator]
pca_variance = 0.999
burn = 100
samples = 100

[calibration]
chains = 4
burn = 300
samples = 500
max_samples = 500  # the reduced size as it is: no extension

[discrepancy]
enabled = false

[predict]
method = "simulator"
runs = 10
"""


def reduced_box(case: str, folder: Path, errors: str = "") -> Path:
    """Copy example ``case`` into ``folder`` with the settings from ``[design]`` on
    replaced by :data:`REDUCED`; ``errors`` is added to its ``[outputs.errors.*]`` table."""
    target = copy_example(case, folder)
    path = target / "study.toml"
    text = path.read_text(encoding="utf-8")
    text = text[: text.index("[design]")] + REDUCED
    if errors:
        head, sep, tail = text.partition("[outputs.errors.")
        table, newline, rest = tail.partition("\n")
        text = f"{head}{sep}{table}{newline}{errors}\n{rest}"
    path.write_text(text, encoding="utf-8")
    return target
