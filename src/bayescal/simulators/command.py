"""Any external program as a simulator: templates in, a CSV file out.

A :class:`CommandSimulator` runs one program per call of ``simulate``, in a
fresh run folder of its own:

1. each template file is rendered with the parameter values and written into
   the run folder (``string.Template`` syntax: ``$R`` or ``${R}``; every
   placeholder must be a declared parameter, ``$$`` is a literal ``$``);
2. the forcing is written as ``forcing.csv`` (column ``time``: seconds since
   the first sample, then one column per input series, in internal units);
3. the command runs with the run folder as its working directory;
4. the output CSV it wrote is read, its columns checked against the forcing
   clock and returned.

Safety
------
The command is an argument list run without a shell (``shell=False``), so
``;``, ``$(...)``, backticks or ``|`` in any argument, file name or value are
passed literally and never execute anything. Placeholders in the arguments
are replaced by exact whole-token lookup (``{run_dir}``, never
``str.format``), so no attribute access or indexing can be expressed.
Templates can only insert parameter values, which must be real numbers.
Relative paths (templates, the executable) are resolved against the study
folder ``base_dir`` and may not leave it; files written into the run folder
may not leave it either.

Failures
--------
A run that exits with a non-zero code, runs past ``timeout`` (the whole
process group is killed, children included), or leaves a missing or
malformed output file raises :class:`CommandFailed`, which carries the exit
code, the tail of the program's standard error and the command. The run
folder of a failed run is kept for inspection (its path is in the message
and in ``CommandFailed.run_dir``); the folder of a successful run is removed.
When the program exits, any process it left running in its process group is
killed as well. The program's standard output and error are written to ``stdout.txt`` and
``stderr.txt`` in the run folder (files, not pipes, so that a grandchild that
keeps them open cannot hang the caller).
"""

from __future__ import annotations

import contextlib
import math
import numbers
import os
import re
import shutil
import signal
import string
import subprocess
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePosixPath
from typing import NoReturn

import numpy as np
import pandas as pd

from bayescal.errors import ConfigError, SimulatorError
from bayescal.simulators.base import Forcing, check_parameters

FORCING_FILE = "forcing.csv"
STDOUT_FILE = "stdout.txt"
STDERR_FILE = "stderr.txt"
STDERR_TAIL = 2000  # characters of standard error kept in CommandFailed.stderr
_MESSAGE_TAIL = 300  # characters of standard error quoted in the one-line message
_RESERVED = frozenset({FORCING_FILE, STDOUT_FILE, STDERR_FILE})
_TOKEN = re.compile(r"\{([^{}]+)\}")
_TOKEN_LIKE = re.compile(r"\{([A-Za-z_][A-Za-z0-9_.\-/]*)\}")


class CommandFailed(SimulatorError):
    """An external program failed, timed out or wrote unusable output.

    Parameters
    ----------
    message
        One-line description of the failure.
    exit_code
        The program's exit status (negative: killed by that signal; ``None``
        if it never started).
    stderr
        The last :data:`STDERR_TAIL` characters of its standard error.
    command
        The argument list that was run, placeholders substituted.
    run_dir
        The run folder, kept for inspection (``None`` if it was removed).
    """

    def __init__(
        self,
        message: str,
        *,
        exit_code: int | None,
        stderr: str,
        command: Sequence[str],
        run_dir: str | None,
        hint: str | None = None,
    ):
        self.exit_code = exit_code
        self.stderr = stderr
        self.command = tuple(command)
        self.run_dir = run_dir
        super().__init__(message, hint=hint)


def _check_identifier(name: str, what: str) -> None:
    if not (isinstance(name, str) and name.isascii() and name.isidentifier()):
        raise ConfigError(
            f"{what} {name!r} is not a valid name",
            hint="use letters, digits and underscores, not starting with a digit",
        )


def _inside(base: Path, relative: str, what: str) -> Path:
    """Resolve ``relative`` against ``base``; refuse anything that leaves ``base``."""
    path = Path(relative)
    if path.is_absolute():
        return path
    resolved = Path(os.path.normpath(base / path))  # lexical: symlinks inside are allowed
    if not resolved.is_relative_to(base):
        raise ConfigError(
            f"{what} {relative!r} points outside the study folder {str(base)!r}",
            hint="use a path inside the study folder, or an absolute path",
        )
    return resolved


def _run_file(name: str, what: str) -> str:
    """Check a file name written or read inside the run folder; return it normalised."""
    pure = PurePosixPath(name)
    if not name or "\\" in name or "\0" in name or pure.is_absolute() or ".." in pure.parts:
        raise ConfigError(
            f"{what} {name!r} must be a relative path inside the run folder, without '..'",
            hint="write e.g. 'params.txt' or 'out/result.csv'",
        )
    normalised = str(pure)
    if normalised in _RESERVED or normalised == ".":
        raise ConfigError(
            f"{what} {name!r} is reserved by the run folder",
            hint=f"choose a name other than {sorted(_RESERVED)}",
        )
    return normalised


def _load_template(path: Path, parameters: tuple[str, ...]) -> str:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read template: {exc.strerror}", source=str(path)) from None
    template = string.Template(text)
    if not template.is_valid():
        raise ConfigError(
            "template has a '$' that is not a placeholder such as $R or ${R}",
            source=str(path),
            hint="write a literal dollar sign as $$",
        )
    unknown = sorted(set(template.get_identifiers()) - set(parameters))
    if unknown:
        raise ConfigError(
            f"template uses placeholder(s) {unknown} that are not parameters {list(parameters)}",
            source=str(path),
            hint="declare them as parameters or write a literal dollar sign as $$",
        )
    return text


def _resolve_executable(program: str, base: Path) -> str:
    if os.sep in program or (os.altsep and os.altsep in program):
        path = _inside(base, program, "executable")
        if not path.is_file():
            raise ConfigError(f"executable {program!r} not found at {str(path)!r}")
        return str(path)
    found = shutil.which(program)
    if found is None:
        raise ConfigError(
            f"executable {program!r} is not on the PATH",
            hint="give its absolute path or a path relative to the study folder",
        )
    return found


def _format_value(value: float) -> str:
    """A parameter value as text that reads back to the same float."""
    return repr(float(value))


def _tail(path: Path, n: int) -> str:
    try:
        data = path.read_bytes()
    except OSError:
        return ""
    return data[-4 * n :].decode("utf-8", errors="replace")[-n:]


class CommandSimulator:
    """Run an external program once per parameter set.

    Parameters
    ----------
    command
        Argument list; the first item is the program (a name on the PATH, an
        absolute path, or a path relative to ``base_dir``). Items may contain
        the placeholders ``{run_dir}``, ``{base_dir}``, ``{forcing_csv}``,
        ``{output_csv}`` (absolute paths), ``{start}`` (ISO 8601 UTC time of
        the first sample), ``{step}`` (time step [s]), ``{n}`` (number of
        samples) and ``{NAME}`` for each rendered template file ``NAME``
        (its absolute path).
    base_dir
        Study folder; relative template and executable paths are resolved
        against it and may not leave it.
    parameters
        Names of the calibration parameters, each used by at least one
        template.
    outputs
        Output name -> column of the output CSV file.
    templates
        Template path (relative to ``base_dir`` or absolute) -> name of the
        rendered file in the run folder.
    inputs
        Forcing series written to ``forcing.csv``, in this column order.
    output_file
        The CSV file (with a header line) the program writes, relative to
        the run folder.
    time_column
        Optional column of the output file with the time since the first
        sample [s]; if given it must match the forcing clock to within 1e-6
        of a step.
    nominal
        Values used for parameters that ``simulate`` is not given.
    timeout
        Wall-clock limit of one run. [s]
    env
        Environment variables added to (or replacing) the caller's.
    work_dir
        Folder in which run folders are created (default: the system's
        temporary folder).
    name
        Short name used in messages.
    """

    def __init__(
        self,
        command: Sequence[str],
        *,
        base_dir: str | os.PathLike[str],
        parameters: Sequence[str],
        outputs: Mapping[str, str],
        templates: Mapping[str, str] | None = None,
        inputs: Sequence[str] = (),
        output_file: str = "out.csv",
        time_column: str | None = None,
        nominal: Mapping[str, float] | None = None,
        timeout: float = 3600.0,
        env: Mapping[str, str] | None = None,
        work_dir: str | os.PathLike[str] | None = None,
        name: str = "command",
    ):
        if isinstance(command, str) or not command or not all(isinstance(a, str) for a in command):
            raise ConfigError(
                f"command must be a non-empty list of strings, got {command!r}",
                hint='write e.g. ["python", "model.py", "{forcing_csv}"]; no shell is used',
            )
        base = Path(base_dir).resolve()
        if not base.is_dir():
            raise ConfigError(f"study folder {str(base)!r} does not exist")
        if not (math.isfinite(timeout) and timeout > 0):
            raise ConfigError(f"timeout must be a positive number of seconds, got {timeout!r}")
        for p in parameters:
            _check_identifier(p, "parameter name")
        self.name = name
        self.base_dir = str(base)
        self._parameters = tuple(parameters)
        self._inputs = tuple(inputs)
        self._outputs = dict(outputs)
        if not self._outputs:
            raise ConfigError("a command simulator needs at least one output column")
        self.output_file = _run_file(output_file, "output file")
        self.time_column = time_column
        self.timeout = float(timeout)
        self.env = {str(k): str(v) for k, v in (env or {}).items()}
        self.work_dir = None if work_dir is None else str(Path(work_dir).resolve())
        self.nominal = self._check_nominal(nominal or {})
        self._templates = self._load_templates(templates or {}, base)
        self.command = (_resolve_executable(command[0], base), *command[1:])
        self._check_placeholders()

    # -- Simulator protocol -------------------------------------------------

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the calibration parameters."""
        return self._parameters

    @property
    def input_names(self) -> tuple[str, ...]:
        """Forcing series written to ``forcing.csv``."""
        return self._inputs

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the returned series."""
        return tuple(self._outputs)

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        """Run the program once.

        Parameters
        ----------
        parameters
            Calibration parameter values (real numbers, in the units the
            templates expect); missing ones take their ``nominal`` value.
        forcing
            Boundary conditions on the study clock.

        Returns
        -------
        dict
            Output name -> series of length ``forcing.n``.

        Raises
        ------
        SimulatorError
            For bad parameter values or a missing forcing series.
        CommandFailed
            If the run fails (see the module documentation).
        """
        values = self._values(parameters)
        forcing.require(self._inputs, who=self.name)
        if forcing.n == 0:
            raise SimulatorError(f"{self.name}: the forcing has no samples")
        run_dir = Path(tempfile.mkdtemp(prefix="bayescal-run-", dir=self.work_dir))
        argv = [self._substitute(a, run_dir, forcing) for a in self.command]
        try:
            self._prepare(run_dir, values, forcing)
            self._execute(argv, run_dir)
            result = self._read_output(argv, run_dir, forcing)
        except CommandFailed:
            raise
        except BaseException:
            shutil.rmtree(run_dir, ignore_errors=True)
            raise
        shutil.rmtree(run_dir, ignore_errors=True)
        return result

    # -- construction helpers ----------------------------------------------

    def _check_nominal(self, nominal: Mapping[str, float]) -> dict[str, float]:
        unknown = sorted(set(nominal) - set(self._parameters))
        if unknown:
            raise ConfigError(f"nominal values given for unknown parameter(s) {unknown}")
        out = {}
        for key, value in nominal.items():
            out[key] = self._number(key, value, ConfigError)
        return out

    def _load_templates(self, templates: Mapping[str, str], base: Path) -> dict[str, str]:
        rendered: dict[str, str] = {}
        for src, dest in templates.items():
            target = _run_file(dest, "rendered template name")
            if target in rendered:
                raise ConfigError(f"two templates render to the same file {target!r}")
            rendered[target] = _load_template(_inside(base, src, "template"), self._parameters)
        used = set()
        for text in rendered.values():
            used.update(string.Template(text).get_identifiers())
        unused = sorted(set(self._parameters) - used)
        if unused:
            raise ConfigError(
                f"parameter(s) {unused} appear in no template, so they would have no effect",
                hint="add $NAME placeholders to a template or remove the parameter",
            )
        return rendered

    def _check_placeholders(self) -> None:
        known = self._known_tokens()
        for arg in self.command[1:]:
            for token in _TOKEN_LIKE.findall(arg):
                if token not in known:
                    raise ConfigError(
                        f"unknown placeholder {{{token}}} in command argument {arg!r}",
                        hint=f"known placeholders: {sorted('{' + k + '}' for k in known)}",
                    )

    def _known_tokens(self) -> set[str]:
        base = {"run_dir", "base_dir", "forcing_csv", "output_csv", "start", "step", "n"}
        return base | set(self._templates)

    # -- one run ------------------------------------------------------------

    @staticmethod
    def _number(name: str, value: object, error: type[Exception]) -> float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise error(f"parameter {name!r} must be a real number, got {value!r}")
        if not math.isfinite(float(value)):
            raise error(f"parameter {name!r} is not finite ({value!r})")
        return float(value)

    def _values(self, parameters: Mapping[str, float]) -> dict[str, float]:
        unknown = sorted(set(parameters) - set(self._parameters))
        if unknown:
            check_parameters({k: 0.0 for k in unknown}, self._parameters, self.name)
        values = dict(self.nominal)
        for key, value in parameters.items():
            values[key] = self._number(key, value, SimulatorError)
        missing = sorted(set(self._parameters) - set(values))
        if missing:
            raise SimulatorError(
                f"{self.name}: no value for parameter(s) {missing} and no nominal value",
                hint="pass them to simulate() or give them nominal values",
            )
        return values

    def _substitute(self, arg: str, run_dir: Path, forcing: Forcing) -> str:
        table = {
            "run_dir": str(run_dir),
            "base_dir": self.base_dir,
            "forcing_csv": str(run_dir / FORCING_FILE),
            "output_csv": str(run_dir / self.output_file),
            "start": str(forcing.times[0]),
            "step": repr(float(forcing.step)),
            "n": str(forcing.n),
        }
        table.update({name: str(run_dir / name) for name in self._templates})
        return _TOKEN.sub(lambda m: table.get(m.group(1), m.group(0)), arg)

    def _prepare(self, run_dir: Path, values: Mapping[str, float], forcing: Forcing) -> None:
        text_values = {k: _format_value(v) for k, v in values.items()}
        for name, text in self._templates.items():
            target = run_dir / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(string.Template(text).substitute(text_values), encoding="utf-8")
        columns = [np.arange(forcing.n) * float(forcing.step)]
        columns += [forcing[name] for name in self._inputs]
        np.savetxt(
            run_dir / FORCING_FILE,
            np.column_stack(columns),
            fmt="%.17g",
            delimiter=",",
            header=",".join(("time", *self._inputs)),
            comments="",
        )

    def _fail(self, message: str, argv: Sequence[str], run_dir: Path, code: int | None) -> NoReturn:
        stderr = _tail(run_dir / STDERR_FILE, STDERR_TAIL)
        quoted = " ".join(stderr[-_MESSAGE_TAIL:].split())
        raise CommandFailed(
            f"{self.name}: {message}" + (f"; stderr ends: {quoted!r}" if quoted else ""),
            exit_code=code,
            stderr=stderr,
            command=argv,
            run_dir=str(run_dir),
            hint=f"run folder kept at {run_dir}",
        )

    def _execute(self, argv: Sequence[str], run_dir: Path) -> None:
        env = {**os.environ, **self.env}
        with (
            open(run_dir / STDOUT_FILE, "wb") as out,
            open(run_dir / STDERR_FILE, "wb") as err,
        ):
            try:
                proc = subprocess.Popen(
                    list(argv),
                    cwd=run_dir,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=err,
                    shell=False,
                    start_new_session=True,
                )
            except OSError as exc:
                self._fail(f"cannot start {argv[0]!r}: {exc.strerror}", argv, run_dir, None)
            timed_out = _wait_or_kill(proc, self.timeout)
        if timed_out:
            self._fail(
                f"{_short(argv)} timed out after {self.timeout:g} s and was killed",
                argv,
                run_dir,
                proc.returncode,
            )
        if proc.returncode != 0:
            self._fail(
                f"{_short(argv)} exited with code {proc.returncode}", argv, run_dir, proc.returncode
            )

    def _read_output(
        self, argv: Sequence[str], run_dir: Path, forcing: Forcing
    ) -> dict[str, np.ndarray]:
        path = run_dir / self.output_file
        if not path.is_file():
            self._fail(f"the program wrote no output file {self.output_file!r}", argv, run_dir, 0)
        try:
            table = pd.read_csv(path, skipinitialspace=True)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
            msg = " ".join(str(exc).split())
            self._fail(f"output file {self.output_file!r} is malformed: {msg}", argv, run_dir, 0)
        wanted = list(self._outputs.values())
        if self.time_column is not None:
            wanted.append(self.time_column)
        missing = [c for c in wanted if c not in table.columns]
        if missing:
            self._fail(
                f"output file {self.output_file!r} lacks column(s) {missing}; "
                f"it has {list(table.columns)}",
                argv,
                run_dir,
                0,
            )
        if len(table) != forcing.n:
            self._fail(
                f"output file {self.output_file!r} has {len(table)} rows, "
                f"the forcing has {forcing.n} samples",
                argv,
                run_dir,
                0,
            )
        result = {}
        for out_name, column in self._outputs.items():
            result[out_name] = self._column(table, column, argv, run_dir)
        if self.time_column is not None:
            t = self._column(table, self.time_column, argv, run_dir)
            expected = np.arange(forcing.n) * float(forcing.step)
            if not np.allclose(t, expected, rtol=0.0, atol=1e-6 * forcing.step):
                bad = int(np.argmax(np.abs(t - expected) > 1e-6 * forcing.step))
                self._fail(
                    f"output time column {self.time_column!r} is off the forcing clock: "
                    f"row {bad} has {float(t[bad])!r} s, expected {float(expected[bad])!r} s",
                    argv,
                    run_dir,
                    0,
                )
        return result

    def _column(
        self, table: pd.DataFrame, column: str, argv: Sequence[str], run_dir: Path
    ) -> np.ndarray:
        try:
            values = pd.to_numeric(table[column], errors="raise").to_numpy(dtype=float)
        except (ValueError, TypeError):
            self._fail(
                f"column {column!r} of {self.output_file!r} is not numeric", argv, run_dir, 0
            )
        if not np.all(np.isfinite(values)):
            bad = int(np.argmin(np.isfinite(values)))
            self._fail(
                f"column {column!r} of {self.output_file!r} has a NaN or infinite value "
                f"(first at row {bad})",
                argv,
                run_dir,
                0,
            )
        return values


def _short(argv: Sequence[str]) -> str:
    text = " ".join(argv)
    return repr(text if len(text) <= 120 else text[:117] + "...")


def _kill_group(pid: int) -> None:
    """Send SIGKILL to the process group led by ``pid`` (the run's own session)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGKILL)


def _wait_or_kill(proc: subprocess.Popen[bytes], timeout: float) -> bool:
    """Wait for ``proc``; on timeout kill its whole process group. Return True on timeout."""
    deadline = time.monotonic() + timeout
    try:
        proc.wait(timeout=max(deadline - time.monotonic(), 0.0))
    except subprocess.TimeoutExpired:
        _kill_group(proc.pid)
        proc.wait()
        return True
    except BaseException:  # KeyboardInterrupt and the like: leave nothing running
        _kill_group(proc.pid)
        proc.wait()
        raise
    # Leftover background children of a finished run are killed too.
    _kill_group(proc.pid)
    return False
