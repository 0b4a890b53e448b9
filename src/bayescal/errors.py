"""Exception types that carry what went wrong and how to fix it.

Every error a user can cause (a bad study file, a malformed data file, an
impossible prior, a simulator that fails) is raised as a subclass of
:class:`BayescalError`. The command-line interface prints such errors as one
line, without a traceback; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations


class BayescalError(Exception):
    """Base class of all user-facing errors.

    Parameters
    ----------
    message
        What was wrong, what was received and what was expected.
    hint
        How to fix it (optional); appended to the message.
    source
        The file, key or column concerned (optional); prefixed to the message.
    """

    def __init__(self, message: str, *, hint: str | None = None, source: str | None = None):
        self.message = message
        self.hint = hint
        self.source = source
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The error as a single line: ``source: message (hint)``."""
        text = f"{self.source}: {self.message}" if self.source else self.message
        if self.hint:
            text = f"{text}; {self.hint}"
        return " ".join(text.split())


class ConfigError(BayescalError):
    """The study file is invalid (unknown key, wrong type, impossible prior...)."""


class DataError(BayescalError):
    """Measured data cannot be read or used (malformed file, gaps, units...)."""


class SimulatorError(BayescalError):
    """A simulator could not be built or a run failed."""


class OutputError(BayescalError):
    """The output folder cannot be written (permission, full or read-only disk, a file in
    its place) or is in use by another run."""
