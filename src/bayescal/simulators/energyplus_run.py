"""Running EnergyPlus and judging its run: a child process (or this one) and ``eplusout.err``.

The child process imports only ``pyenergyplus`` (not bayescal, whose imports
cost seconds); see :mod:`bayescal.simulators.energyplus` for why runs happen
in a child process by default.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bayescal.errors import SimulatorError

__all__ = [
    "check_errors",
    "error_messages",
    "require_pyenergyplus",
    "run_energyplus",
    "run_energyplus_in_process",
]

_MAX_MESSAGES = 3
# The child process imports only pyenergyplus (not bayescal, whose imports cost seconds).
_WORKER = """
import sys
from pyenergyplus.api import EnergyPlusAPI
api = EnergyPlusAPI()
state = api.state_manager.new_state()
api.runtime.set_console_output_status(state, False)
code = api.runtime.run_energyplus(state, sys.argv[1:])
api.state_manager.delete_state(state)
sys.exit(int(code))
"""


def require_pyenergyplus() -> None:
    """Raise :class:`SimulatorError` with the install hint unless pyenergyplus is installed."""
    if importlib.util.find_spec("pyenergyplus") is None:
        raise SimulatorError(
            "the EnergyPlus simulator needs the package pyenergyplus-lbnl",
            hint="pip install 'bayescal[energyplus]'",
        )


def run_energyplus(arguments: Sequence[str], timeout: float, cwd: Path) -> int:
    """Run EnergyPlus with command-line ``arguments`` in a child Python process.

    Parameters
    ----------
    arguments
        EnergyPlus command-line arguments (``-w``, ``-d``, model...).
    timeout
        Seconds after which the run is killed. [s]
    cwd
        Working directory of the child.

    Returns
    -------
    int
        EnergyPlus's exit code (errors are judged from ``eplusout.err``).
    """
    command = [sys.executable, "-c", _WORKER, *arguments]
    try:
        done = subprocess.run(
            command, cwd=cwd, timeout=timeout, capture_output=True, text=True, check=False
        )
    except subprocess.TimeoutExpired:
        raise SimulatorError(
            f"EnergyPlus run exceeded the timeout of {timeout:g} s and was stopped",
            hint="raise the simulator's timeout or shorten the forcing",
        ) from None
    if done.returncode not in (0, 1):  # 1: EnergyPlus reported errors in eplusout.err
        tail = " ".join(done.stderr.strip().splitlines()[-3:])
        raise SimulatorError(f"EnergyPlus process ended with code {done.returncode}: {tail}")
    return done.returncode


def run_energyplus_in_process(arguments: Sequence[str], timeout: float) -> int:
    """Run EnergyPlus in this process with a fresh API state (see ``isolation``).

    Parameters
    ----------
    arguments
        EnergyPlus command-line arguments.
    timeout
        Seconds after which the run is asked to stop at its next zone time step. [s]

    Returns
    -------
    int
        EnergyPlus's exit code.
    """
    from pyenergyplus.api import EnergyPlusAPI

    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    deadline = time.monotonic() + timeout
    stopped: list[bool] = []

    def watchdog(run_state: Any) -> None:
        if not stopped and time.monotonic() > deadline:
            stopped.append(True)
            api.runtime.stop_simulation(run_state)

    api.runtime.callback_begin_zone_timestep_before_init_heat_balance(state, watchdog)
    try:
        code = int(api.runtime.run_energyplus(state, list(arguments)))
    finally:
        api.state_manager.delete_state(state)
    if stopped:
        raise SimulatorError(
            f"EnergyPlus run exceeded the timeout of {timeout:g} s and was stopped",
            hint="raise the simulator's timeout or shorten the forcing",
        )
    return code


def error_messages(err_text: str) -> list[str]:
    """Severe and fatal messages of an ``eplusout.err`` text, continuation lines joined."""
    messages: list[str] = []
    current: list[str] | None = None
    for line in err_text.splitlines():
        stripped = line.strip()
        if stripped.startswith(("** Severe  **", "**  Fatal  **")):
            current = [stripped]
            messages.append("")
        elif current is not None and stripped.startswith("**   ~~~   **"):
            current.append(stripped.removeprefix("**   ~~~   **").strip())
        else:
            current = None
        if current is not None:
            messages[-1] = " ".join(current)
    return messages


#: Severe messages that do not fail a run: EnergyPlus's warm-up did not converge within its
#: maximum number of warm-up days (a building with much thermal mass, a start in a cold
#: spell). The run goes on from the last warm-up day, and the warm-up days that the adapter
#: simulates before the first sample (``warmup_days``) settle the state before it is used.
TOLERATED = ("CheckWarmupConvergence",)


def check_errors(err_file: Path, *, source: str | None = None) -> None:
    """Raise :class:`SimulatorError` unless ``eplusout.err`` shows a clean, complete run.

    Severe messages in :data:`TOLERATED` do not count.
    """
    if not err_file.is_file():
        raise SimulatorError("EnergyPlus wrote no eplusout.err", source=source)
    text = err_file.read_text(encoding="utf-8", errors="replace")
    messages = [m for m in error_messages(text) if not any(t in m for t in TOLERATED)]
    completed = "EnergyPlus Completed Successfully" in text
    if messages or not completed:
        shown = (
            " | ".join(messages[:_MAX_MESSAGES]) or "no Severe message; the run did not complete"
        )
        more = len(messages) - _MAX_MESSAGES
        raise SimulatorError(
            f"EnergyPlus run failed: {shown}" + (f" (+{more} more)" if more > 0 else ""),
            hint="see eplusout.err of the run (keep_outputs = true keeps it)",
            source=source,
        )
