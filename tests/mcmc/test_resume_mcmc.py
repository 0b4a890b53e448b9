"""MCMC checkpoints: a chain killed midway resumes with draws identical to an uninterrupted one."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.mcmc.chains import run_chains
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs
from bayescal.store.posterior import load_posterior

SAMPLER = MetropolisWithinGibbs(n_burn=300, lower=[0.0, -np.inf], batch_size=25, max_adapt=0.1)


class Interrupt(Exception):
    """Stands for a kill: raised by the target after a number of evaluations."""


class Target:
    """A correlated 2-D target (x0 > 0) that 'dies' after ``limit`` evaluations."""

    def __init__(self, limit: int | None = None) -> None:
        self.limit, self.calls = limit, 0

    def __call__(self, x: np.ndarray) -> float:
        self.calls += 1
        if self.limit is not None and self.calls > self.limit:
            raise Interrupt
        return float(-0.5 * ((np.log(x[0]) - x[1]) ** 2 / 0.1 + x[1] ** 2) - np.log(x[0]))


def _run(target: Target, folder: Path | None) -> np.ndarray:
    chains = run_chains(
        SAMPLER,
        target,
        [[1.0, 0.0], [2.0, 0.5]],
        500,
        seed=11,
        backend="serial",
        checkpoint_dir=folder,
        checkpoint_seconds=0.0,
    )
    return chains.draws


@pytest.mark.parametrize("limit", [100, 1234, 3000])
def test_interrupted_chains_resume_identically(tmp_path: Path, limit: int) -> None:
    reference = _run(Target(), None)
    with pytest.raises(Interrupt):
        _run(Target(limit), tmp_path)
    assert list(tmp_path.glob("chain-*.npz")), "a snapshot must exist after the interruption"
    resumed_target = Target()
    resumed = _run(resumed_target, tmp_path)
    np.testing.assert_array_equal(resumed, reference)
    # The work before the last snapshot was not redone: fewer evaluations than a fresh run
    # (2 chains x 800 sweeps x 2 coordinates + 2 starts = 3202).
    assert resumed_target.calls < 3202


def test_stale_snapshot_is_ignored(tmp_path: Path) -> None:
    _run(Target(), tmp_path)  # complete snapshots of seed 11
    other = run_chains(
        SAMPLER,
        Target(),
        [[1.0, 0.0], [2.0, 0.5]],
        500,
        seed=12,
        backend="serial",
        checkpoint_dir=tmp_path,
        checkpoint_seconds=0.0,
    )
    fresh = run_chains(SAMPLER, Target(), [[1.0, 0.0], [2.0, 0.5]], 500, seed=12, backend="serial")
    np.testing.assert_array_equal(other.draws, fresh.draws)


class BatchTarget(Target):
    """:class:`Target` evaluated for all chains at once (``batch``), dying after ``limit`` calls."""

    def batch(self, points: np.ndarray) -> np.ndarray:
        self.calls += 1
        if self.limit is not None and self.calls > self.limit:
            raise Interrupt
        x0, x1 = points[:, 0], points[:, 1]
        return -0.5 * ((np.log(x0) - x1) ** 2 / 0.1 + x1**2) - np.log(x0)


def _run_lockstep(target: Target, folder: Path | None) -> np.ndarray:
    chains = run_chains(
        SAMPLER,
        target,
        [[1.0, 0.0], [2.0, 0.5], [0.5, -0.5], [1.5, 1.0]],
        500,
        seed=11,
        backend="vectorised",
        checkpoint_dir=folder,
        checkpoint_seconds=0.0,
    )
    return chains.draws


@pytest.mark.parametrize("limit", [60, 777, 1500])
def test_interrupted_lockstep_chains_resume_identically(tmp_path: Path, limit: int) -> None:
    reference = _run_lockstep(BatchTarget(), None)
    with pytest.raises(Interrupt):
        _run_lockstep(BatchTarget(limit), tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["lockstep.npz"]
    resumed_target = BatchTarget()
    resumed = _run_lockstep(resumed_target, tmp_path)
    np.testing.assert_array_equal(resumed, reference)
    # Fresh: 1 start + 800 sweeps x 2 coordinates = 1601 batched calls. Killed at call
    # `limit`, (limit - 1) // 2 sweeps were done and every finished batch of 25 was
    # snapshotted; the resumed run does only the rest (+ 1 call to rebuild the state).
    kept = 25 * (((limit - 1) // 2) // 25)
    assert resumed_target.calls == 2 * (800 - kept) + 1


def _run_groups(target: Target, folder: Path | None) -> np.ndarray:
    chains = run_chains(
        SAMPLER,
        target,
        [[1.0, 0.0], [2.0, 0.5], [0.5, -0.5], [1.5, 1.0]],
        500,
        seed=11,
        backend="vectorised-processes",
        max_workers=2,
        checkpoint_dir=folder,
        checkpoint_seconds=0.0,
    )
    return chains.draws


@pytest.mark.parametrize("limit", [60, 1500])
def test_interrupted_lockstep_groups_in_processes_resume_identically(
    tmp_path: Path, limit: int
) -> None:
    # Two lockstep groups of two chains, one per worker process; each worker's copy
    # of the target dies after `limit` batched calls.
    reference = _run_lockstep(BatchTarget(), None)
    np.testing.assert_array_equal(_run_groups(BatchTarget(), None), reference)
    with pytest.raises(Interrupt):
        _run_groups(BatchTarget(limit), tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lockstep-0.npz", "lockstep-1.npz"]
    resumed = _run_groups(BatchTarget(), tmp_path)
    np.testing.assert_array_equal(resumed, reference)


# A finished run's last snapshot extends it: the same call with more draws resumes and
# keeps sampling, with the draws of a run that asked for that many from the start.
JOINT = MetropolisWithinGibbs(
    n_burn=300,
    lower=[0.0, -np.inf],
    batch_size=25,
    max_adapt=0.1,
    joint=[0, 1],
    joint_after_burn=2,
    screen=True,
)
STARTS = [[1.0, 0.0], [2.0, 0.5], [0.5, -0.5], [1.5, 1.0]]


def _extend(folder: Path, sampler: MetropolisWithinGibbs, backend: str, draws: int) -> tuple:
    target = BatchTarget()
    chains = run_chains(
        sampler,
        target,
        STARTS,
        draws,
        seed=11,
        backend=backend,  # type: ignore[arg-type]
        max_workers=2,
        checkpoint_dir=folder,
        checkpoint_seconds=0.0,
    )
    return chains.draws, chains.log_density, chains.acceptance, target.calls


@pytest.mark.parametrize("sampler", [SAMPLER, JOINT], ids=["gibbs", "joint-screened"])
@pytest.mark.parametrize("backend", ["serial", "vectorised", "vectorised-processes"])
def test_a_finished_run_extends_to_the_draws_of_a_longer_run(
    tmp_path: Path, sampler: MetropolisWithinGibbs, backend: str
) -> None:
    longer = _extend(tmp_path / "reference", sampler, backend, 770)
    _extend(tmp_path / "extended", sampler, backend, 500)  # kept sweeps fill 20 batches
    draws, lps, acceptance, calls = _extend(tmp_path / "extended", sampler, backend, 770)
    np.testing.assert_array_equal(draws, longer[0])
    np.testing.assert_array_equal(lps, longer[1])
    np.testing.assert_allclose(acceptance, longer[2], rtol=1e-12)
    if backend == "serial":  # evaluations in this process: only the extra 270 sweeps
        assert 0 < calls < longer[3] / 3
    # A snapshot that has run past the requested length is not cut back: a fresh run.
    shorter = _extend(tmp_path / "extended", sampler, backend, 400)
    fresh = _extend(tmp_path / "fresh", sampler, backend, 400)
    np.testing.assert_array_equal(shorter[0], fresh[0])


@pytest.mark.parametrize("backend", ["serial", "vectorised"])
def test_a_run_ending_in_a_short_batch_extends_its_own_chains(tmp_path: Path, backend: str) -> None:
    # 510 kept sweeps end in a batch of 10: a generator draws a batch's numbers at once,
    # so the extension continues these chains (same state, frozen widths) without
    # matching a run of 770 from the start; it is reproducible and keeps the 510 draws.
    first = _extend(tmp_path / "a", JOINT, backend, 510)
    extended = _extend(tmp_path / "a", JOINT, backend, 770)
    _extend(tmp_path / "b", JOINT, backend, 510)
    again = _extend(tmp_path / "b", JOINT, backend, 770)
    np.testing.assert_array_equal(extended[0][:, :510], first[0])
    np.testing.assert_array_equal(extended[0], again[0])
    assert np.all(np.isfinite(extended[1]))


SCRIPT = """
import sys
from bayescal.config import load_study
from bayescal.pipeline import Options, run
run(load_study(sys.argv[1]), until="calibrate",
    options=Options(backend="serial", chains_backend=sys.argv[2], checkpoint_seconds=0.0))
"""

FAST = """
[emulator]
pca_variance = 0.99
burn = 100
samples = 100

[calibration]
chains = 4
burn = 600
samples = 1500
max_samples = 1500
"""


def _study(folder: Path, samples: int = 1500) -> Path:
    result = CliRunner().invoke(main, ["init", "wall", str(folder)])
    assert result.exit_code == 0, result.output
    text = (folder / "study.toml").read_text(encoding="utf-8")
    fast = FAST.replace("samples = 1500", f"samples = {samples}")
    (folder / "study.toml").write_text(text[: text.index("[emulator]")] + fast, "utf-8")
    return folder


def _python(study: Path, chains: str) -> subprocess.Popen[bytes]:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return subprocess.Popen(
        [sys.executable, "-c", SCRIPT, str(study), chains], env=env, start_new_session=True
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    ("chains", "snapshot", "samples"),
    # "auto" runs the calibration as lockstep groups in worker processes, about
    # three times faster: more sweeps leave time to kill it midway.
    [("serial", "chain-*.npz", 1500), ("auto", "lockstep*.npz", 8000)],
)
def test_sigkill_in_the_calibration_stage_resumes_identically(
    tmp_path: Path, chains: str, snapshot: str, samples: int
) -> None:
    reference = _study(tmp_path / "reference", samples)
    assert _python(reference, chains).wait(timeout=600) == 0
    expected = load_posterior(reference / "out" / "posterior.nc").draws

    study = _study(tmp_path / "killed", samples)
    rng = np.random.default_rng(5)
    proc = _python(study, chains)
    deadline = time.monotonic() + 300
    snapshots = study / "out" / "checkpoints"
    # Wait for the calibration's first snapshot, then kill at a random later moment:
    # the whole process group, worker processes included (as a killed job is).
    while not list(snapshots.glob(f"calibrate-*/{snapshot}")):
        assert proc.poll() is None, "the run ended before the calibration checkpointed"
        assert time.monotonic() < deadline
        time.sleep(0.05)
    time.sleep(float(rng.uniform(0.2, 1.5)))
    assert proc.poll() is None, "the calibration finished before it could be killed"
    os.killpg(proc.pid, signal.SIGKILL)
    assert proc.wait() == -signal.SIGKILL
    assert not (study / "out" / "posterior.nc").exists()
    folder = study / "out" / "simulations" / "runs"
    runs_before = sorted(p.name for p in folder.iterdir())
    stats_before = {n: (folder / n).stat().st_mtime_ns for n in runs_before}
    assert _python(study, chains).wait(timeout=600) == 0
    draws = load_posterior(study / "out" / "posterior.nc").draws
    np.testing.assert_array_equal(draws, expected)
    # No finished simulator run was repeated, and the snapshots are gone.
    runs_after = sorted(p.name for p in (study / "out" / "simulations" / "runs").iterdir())
    assert runs_after == runs_before
    for n in runs_after:
        assert (folder / n).stat().st_mtime_ns == stats_before[n]
    assert not list(snapshots.glob("calibrate-*"))
