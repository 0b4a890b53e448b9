"""Where the test suite's files are, independent of the test module's folder."""

from __future__ import annotations

from pathlib import Path

HELPERS = Path(__file__).resolve().parent
TESTS = HELPERS.parent
REPO = TESTS.parent
#: Small study folders and data files the tests read (never the shared data).
FIXTURES = HELPERS / "fixtures"
#: External programs the command-simulator tests run.
PROGRAMS = HELPERS / "programs"
#: C sources of the FMUs the FMU tests build.
FMU_SRC = HELPERS / "fmu_src"
#: The real measured data beside the repository (absent in a fresh clone: tests skip).
SHARED_DATA = REPO.parent / "shared" / "data"
