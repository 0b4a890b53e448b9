"""The runner: per-run cache, resume, backends, and fault handling."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import sims_for_tests as sims
from bayescal.design import UniformPrior, latin_hypercube
from bayescal.errors import ConfigError, SimulatorError
from bayescal.runner import (
    forcing_fingerprint,
    run_design,
    run_key,
    sandbox,
    simulator_fingerprint,
)
from bayescal.simulators.base import Forcing
from bayescal.simulators.wrappers import SensorModel, TargetedSimulator
from paths import HELPERS

HERE = HELPERS
N = 48
FORCING = Forcing(3600.0, {"temp_air_out": 10.0 + 5.0 * np.sin(np.arange(N) / 3.0)})
PRIORS = {"a": UniformPrior(0.0, 1.0), "b": UniformPrior(-1.0, 1.0)}
# 10 runs: a Latin hypercube puts exactly one value of a in [0.9, 1), the run the
# faulty simulators (threshold 0.9) break.
DESIGN = latin_hypercube(PRIORS, 10, seed=1)
BAD = int(np.flatnonzero(DESIGN.values[:, 0] >= 0.9)[0])
TIMEOUT = 2.0  # [s] long enough for a worker start plus one cheap run, short for the test


def _assert_matches_reference(results, rows) -> None:
    assert results.indices.tolist() == list(rows)
    for i, row in enumerate(rows):
        ref = sims.reference(*DESIGN.values[row], FORCING)
        # 1e-12: the simulator and the reference evaluate the same formula in a
        # different order; only rounding differs.
        np.testing.assert_allclose(results.outputs["y"][i], ref["y"], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(results.outputs["z"][i], ref["z"], rtol=1e-12, atol=1e-12)


def _npz_files(cache: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in (cache / "runs").glob("*.npz")}


# ------------------------------------------------------------------ fingerprints


def test_fingerprint_is_stable_across_processes() -> None:
    code = textwrap.dedent(
        f"""
        import sys; sys.path.insert(0, {str(HERE)!r})
        import numpy as np, sims_for_tests as sims
        from bayescal.runner import simulator_fingerprint, forcing_fingerprint
        from bayescal.simulators.base import Forcing
        f = Forcing(3600.0, {{"temp_air_out": 10.0 + 5.0 * np.sin(np.arange({N}) / 3.0)}})
        print(simulator_fingerprint(sims.Failing(threshold=0.5)), forcing_fingerprint(f))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    here = f"{simulator_fingerprint(sims.Failing(threshold=0.5))} {forcing_fingerprint(FORCING)}"
    assert out.stdout.split() == here.split()


def test_fingerprint_distinguishes_configurations() -> None:
    assert simulator_fingerprint(sims.Analytic()) != simulator_fingerprint(sims.Analytic(2.0))
    assert simulator_fingerprint(sims.Failing(0.5)) != simulator_fingerprint(sims.Hanging(0.5))
    shifted = Forcing(3600.0, {"temp_air_out": FORCING["temp_air_out"] + 1e-9})
    assert forcing_fingerprint(shifted) != forcing_fingerprint(FORCING)
    # fingerprint() wins over the attributes (here a cache that changes as it runs).
    sim = sims.WithFingerprint("v1")
    before = simulator_fingerprint(sim)
    sim.simulate({"a": 0.1, "b": 0.2}, FORCING)
    assert simulator_fingerprint(sim) == before != simulator_fingerprint(sims.WithFingerprint("v2"))
    values = (0.2, 0.2 + 1e-18, float(np.nextafter(0.2, 1.0)))  # equal, equal, 1 ulp above
    keys = [run_key("s", "f", {"a": 0.1, "b": b}) for b in values]
    assert keys[0] == keys[1] != keys[2]


def test_moved_wrappers_keep_their_fingerprints() -> None:
    """Runs cached before the wrappers left ``simulators.factory`` (issue 14) are found again."""
    targeted = TargetedSimulator(sims.Analytic(), {"p": ("a",), "q": ("b",)})
    sensor = SensorModel(targeted, ("p", "q", "g"), {"g": (("y", "gain"),)})
    # Fingerprints computed with the classes in bayescal.simulators.factory (commit 4120a10).
    assert simulator_fingerprint(targeted) == (
        "cf678cc1585edaf6a3bea7f5ae049bbe30363c6ecc50b8c181a95ec6873f9d46"
    )
    assert simulator_fingerprint(sensor) == (
        "f009d39192a86b5539a362a575f7973488682b3ce84d72f17e19cc30ae32fa65"
    )


def test_fingerprint_refuses_unstable_state() -> None:
    with pytest.raises(SimulatorError, match=r"repr changes between processes.*fingerprint\(\)"):
        simulator_fingerprint(sims.Opaque())


# ------------------------------------------------------------ cache and resume


def test_serial_runs_caches_and_resumes(tmp_path: Path) -> None:
    calls: list[tuple[int, int, int]] = []
    first = run_design(
        sims.Analytic(),
        FORCING,
        DESIGN,
        cache_dir=tmp_path,
        backend="serial",
        progress=lambda *a: calls.append(a),
    )
    assert (first.n_run, first.n_cached, first.n_attempts, first.n_failed) == (10, 0, 10, 0)
    assert first.outputs["y"].shape == (10, N)
    np.testing.assert_array_equal(first.indices, np.arange(10))
    _assert_matches_reference(first, range(10))
    assert calls[0] == (0, 0, 10)
    assert calls[-1] == (10, 0, 10)
    assert [c[0] for c in calls] == sorted(c[0] for c in calls)
    assert len(_npz_files(tmp_path)) == 10

    second = run_design(sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial")
    assert (second.n_run, second.n_cached, second.n_attempts) == (0, 10, 0)
    for name in ("y", "z"):
        np.testing.assert_array_equal(second.outputs[name], first.outputs[name])

    # Remove three runs and spoil a fourth: exactly those four run again.
    files = sorted((tmp_path / "runs").glob("*.npz"))
    for path in files[:3]:
        path.unlink()
    files[3].write_bytes(files[3].read_bytes()[:100])
    third = run_design(sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial")
    assert (third.n_run, third.n_cached) == (4, 6)
    np.testing.assert_array_equal(third.outputs["y"], first.outputs["y"])

    other = run_design(
        sims.Analytic(gain=2.0), FORCING, DESIGN, cache_dir=tmp_path, backend="serial"
    )
    assert other.n_run == 10  # another configuration: nothing reused
    np.testing.assert_allclose(other.outputs["y"], 2 * first.outputs["y"], rtol=1e-15)


def test_cache_file_contents(tmp_path: Path) -> None:
    results = run_design(sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial")
    with np.load(tmp_path / "runs" / f"{results.keys[4]}.npz", allow_pickle=False) as archive:
        assert archive["parameter_names"].tolist() == ["a", "b"]
        np.testing.assert_array_equal(archive["parameter_values"], DESIGN.values[4])
        np.testing.assert_array_equal(archive["out:y"], results.outputs["y"][4])
        metadata = json.loads(str(archive["metadata"]))
    assert metadata["key"] == results.keys[4]
    assert metadata["simulator"] == "sims_for_tests.Analytic"
    assert metadata["attempts"] == 1


def test_processes_equal_serial(tmp_path: Path) -> None:
    serial = run_design(
        sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path / "s", backend="serial"
    )
    parallel = run_design(
        sims.Chatty(), FORCING, DESIGN, cache_dir=tmp_path / "p", backend="processes", jobs=2
    )
    assert parallel.n_run == 10
    for name in ("y", "z"):
        np.testing.assert_array_equal(parallel.outputs[name], serial.outputs[name])


# ------------------------------------------------------------------- failures


def test_failing_run_is_dropped_and_recorded(tmp_path: Path) -> None:
    results = run_design(
        sims.Failing(), FORCING, DESIGN, cache_dir=tmp_path, backend="processes", jobs=2, retries=2
    )
    assert results.n_run == 9
    assert results.n_attempts == 9 + 3  # the failing run is tried 1 + retries times
    assert BAD not in results.indices.tolist()
    assert results.outputs["y"].shape == (9, N)
    _assert_matches_reference(results, [i for i in range(10) if i != BAD])
    (failure,) = results.failures
    assert (failure.index, failure.attempts) == (BAD, 3)
    assert failure.error_type == "bayescal.errors.SimulatorError"
    assert failure.message.startswith("diverged at a=0.9")
    record = json.loads((tmp_path / "failures" / f"{failure.key}.json").read_text())
    assert len(record["attempts"]) == 3
    assert "diverged" in record["attempts"][0]["traceback"]
    assert record["parameters"] == DESIGN.row(BAD)

    # A failure is not cached: the next call tries it again, and clears the record on success.
    fixed = run_design(sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial")
    assert fixed.n_run == 10  # another simulator, other keys
    again = run_design(sims.Failing(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial")
    assert (again.n_run, again.n_cached, again.n_attempts) == (0, 9, 1)


def test_external_failure_keeps_exit_code_and_stderr(tmp_path: Path) -> None:
    results = run_design(
        sims.FailingExternal(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial"
    )
    (failure,) = results.failures
    assert (failure.exit_code, failure.stderr) == (7, "** Severe: no convergence")
    record = json.loads((tmp_path / "failures" / f"{failure.key}.json").read_text())
    assert record["attempts"][0]["exit_code"] == 7


def test_bad_output_shape_is_a_failed_run(tmp_path: Path) -> None:
    results = run_design(sims.BadShape(), FORCING, DESIGN, cache_dir=tmp_path, backend="serial")
    (failure,) = results.failures
    assert failure.message == f"output 'y' has shape ({N - 1},), expected ({N},)"


def test_hanging_run_is_killed_by_the_timeout(tmp_path: Path) -> None:
    start = time.monotonic()
    results = run_design(
        sims.Hanging(),
        FORCING,
        DESIGN,
        cache_dir=tmp_path,
        backend="processes",
        jobs=2,
        timeout=TIMEOUT,
    )
    elapsed = time.monotonic() - start
    assert elapsed < 20  # the hung run sleeps an hour; generous for a loaded CI machine
    assert results.n_run == 9
    _assert_matches_reference(results, [i for i in range(10) if i != BAD])
    (failure,) = results.failures
    assert (failure.index, failure.error_type) == (BAD, "timeout")
    assert "timeout of 2 s" in failure.message


def test_timeout_clock_starts_once_the_worker_is_ready(tmp_path: Path) -> None:
    # Loading takes 1.5 s, a run microseconds: a 1 s timeout must not count the loading.
    sim = sims.SlowToLoad(load_delay=1.5)
    results = run_design(sim, FORCING, DESIGN, cache_dir=tmp_path, jobs=2, timeout=1.0)
    assert (results.n_run, results.n_failed) == (10, 0)


def test_worker_that_never_starts_is_stopped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sandbox, "STARTUP_LIMIT", 0.5)
    design = latin_hypercube(PRIORS, 4, seed=0)
    sim = sims.SlowToLoad(load_delay=30.0)
    results = run_design(sim, FORCING, design, cache_dir=tmp_path, jobs=2, timeout=1.0)
    assert results.n_run == 0
    assert results.outputs["y"].shape == (0, N)
    assert {f.message for f in results.failures} == {
        "the worker process did not start within 0.5 s"
    }


def test_crashing_worker_is_a_failed_run(tmp_path: Path) -> None:
    results = run_design(
        sims.Crashing(), FORCING, DESIGN, cache_dir=tmp_path, backend="processes", jobs=2, retries=1
    )
    assert results.n_run == 9
    _assert_matches_reference(results, [i for i in range(10) if i != BAD])
    (failure,) = results.failures
    assert (failure.index, failure.error_type, failure.exit_code) == (BAD, "worker-died", 3)
    assert failure.attempts == 2
    assert "exit code 3" in failure.message


def test_retries_rescue_flaky_runs(tmp_path: Path) -> None:
    (tmp_path / "markers").mkdir()
    flaky = sims.Flaky(marker_dir=str(tmp_path / "markers"))
    results = run_design(
        flaky, FORCING, DESIGN, cache_dir=tmp_path / "c", backend="processes", jobs=2, retries=1
    )
    assert (results.n_run, results.n_failed, results.n_attempts) == (10, 0, 20)
    _assert_matches_reference(results, range(10))
    assert not list((tmp_path / "c" / "failures").glob("*.json"))


def test_run_killed_midway_resumes_without_redoing_runs(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    script = textwrap.dedent(
        f"""
        import sys; sys.path[:0] = [{str(HERE)!r}, {str(Path(__file__).resolve().parent)!r}]
        import test_runner as t, sims_for_tests as sims
        from bayescal.runner import run_design
        run_design(sims.Slow(delay=0.4), t.FORCING, t.DESIGN, cache_dir={str(cache)!r},
                   backend="processes", jobs=1)
        """
    )
    victim = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 60
        while len(_npz_files(cache)) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        os.kill(victim.pid, signal.SIGKILL)
        victim.wait()
    assert victim.returncode == -signal.SIGKILL
    before = _npz_files(cache)
    assert 3 <= len(before) < 10

    resumed = run_design(
        sims.Slow(delay=0.4), FORCING, DESIGN, cache_dir=cache, backend="processes", jobs=2
    )
    assert (resumed.n_cached, resumed.n_run) == (len(before), 10 - len(before))
    after = _npz_files(cache)
    assert {name: after[name] for name in before} == before  # finished runs untouched
    clean = run_design(
        sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path / "clean", backend="serial"
    )
    for name in ("y", "z"):
        np.testing.assert_array_equal(resumed.outputs[name], clean.outputs[name])


# ------------------------------------------------------------------------ Dask


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as local:
        yield local


def test_dask_equals_serial_and_handles_faults(tmp_path: Path, cluster) -> None:
    address = cluster.scheduler_address
    serial = run_design(
        sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path / "s", backend="serial"
    )
    dask = run_design(
        sims.Analytic(),
        FORCING,
        DESIGN,
        cache_dir=tmp_path / "d",
        backend="dask",
        scheduler=address,
    )
    assert (dask.n_run, dask.n_failed) == (10, 0)
    for name in ("y", "z"):
        np.testing.assert_array_equal(dask.outputs[name], serial.outputs[name])

    for sim, kind in [(sims.Hanging(), "timeout"), (sims.Crashing(), "worker-died")]:
        results = run_design(
            sim,
            FORCING,
            DESIGN,
            cache_dir=tmp_path / kind,
            backend="dask",
            scheduler=address,
            timeout=TIMEOUT,
        )
        assert results.n_run == 9
        _assert_matches_reference(results, [i for i in range(10) if i != BAD])
        (failure,) = results.failures
        assert (failure.index, failure.error_type) == (BAD, kind)
    # Each Dask worker is still alive and serving.
    assert len(cluster.scheduler_info["workers"]) == 2


@pytest.mark.slow
def test_dask_local_cluster_created_by_the_runner(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    serial = run_design(
        sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path / "s", backend="serial"
    )
    results = run_design(
        sims.Failing(), FORCING, DESIGN, cache_dir=tmp_path / "d", backend="dask", jobs=2
    )
    assert results.n_run == 9
    np.testing.assert_array_equal(results.outputs["y"], np.delete(serial.outputs["y"], BAD, axis=0))


# ---------------------------------------------------------------- options, bar


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"backend": "threads"}, "unknown backend 'threads'"),
        ({"backend": "serial", "timeout": 5.0}, "'serial' cannot stop a run"),
        (
            {"backend": "processes", "scheduler": "tcp://x:8786"},
            "scheduler address needs backend='dask'",
        ),
        ({"jobs": 0}, "jobs must be a positive integer, got 0"),
        ({"retries": -1}, "retries must be a non-negative integer"),
        ({"timeout": 0.0}, "timeout must be a positive number"),
    ],
)
def test_bad_options(tmp_path: Path, options, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        run_design(sims.Analytic(), FORCING, DESIGN, cache_dir=tmp_path, **options)


def test_design_must_match_simulator(tmp_path: Path) -> None:
    design = latin_hypercube({"a": UniformPrior(0, 1), "k": UniformPrior(0, 1)}, 5, seed=0)
    with pytest.raises(ConfigError, match=r"design parameter\(s\) \['k'\] are not parameters"):
        run_design(sims.Analytic(), FORCING, design, cache_dir=tmp_path)
    no_temp = Forcing(3600.0, {"temp_air_in": np.zeros(N)})
    with pytest.raises(SimulatorError, match=r"needs boundary condition\(s\) \['temp_air_out'\]"):
        run_design(sims.Analytic(), no_temp, DESIGN, cache_dir=tmp_path)


# --------------------------------------------------------- the built-in wall


def test_multilayer_wall_through_the_runner(tmp_path: Path) -> None:
    from bayescal.simulators.fvm import Layer
    from bayescal.simulators.wall import MultilayerWall

    def make_wall() -> MultilayerWall:
        layers = [
            Layer("brick", 0.1, 0.8, 1800.0, 900.0),
            Layer("insulation", 0.05, 0.04, 30.0, 1400.0),
        ]
        targets = {"k_brick": "brick.conductivity", "k_ins": "insulation.conductivity"}
        return MultilayerWall(layers, parameters=targets)

    wall = make_wall()
    n = 96
    hours = np.arange(n) / 2.0
    forcing = Forcing(
        1800.0,
        {
            "temp_surf_out": 5.0 + 8.0 * np.sin(2 * np.pi * hours / 24.0),
            "temp_surf_in": np.full(n, 20.0),
        },
    )
    priors = {"k_brick": UniformPrior(0.5, 1.2), "k_ins": UniformPrior(0.03, 0.05)}
    design = latin_hypercube(priors, 6, seed=2)
    results = run_design(wall, forcing, design, cache_dir=tmp_path, backend="processes", jobs=2)
    assert results.outputs["heat_flux_in"].shape == (6, n)
    for i in range(6):
        direct = wall.simulate(design.row(i), forcing)["heat_flux_in"]
        # Same code on the same machine in another process: equal up to the last bits
        # that a multithreaded BLAS might order differently.
        np.testing.assert_allclose(
            results.outputs["heat_flux_in"][i], direct, rtol=1e-12, atol=1e-12
        )
    # A wall built again from the same description has the same fingerprint: cache hits.
    again = run_design(make_wall(), forcing, design, cache_dir=tmp_path, backend="processes")
    assert (again.n_run, again.n_cached) == (0, 6)


@pytest.mark.slow
def test_load_1000_runs_with_failures_and_hangs(tmp_path: Path) -> None:
    from bayescal.report.html import _failures

    priors = {"a": UniformPrior(0.0, 1.0), "b": UniformPrior(0.0, 1.0)}
    design = latin_hypercube(priors, 1000, seed=4)
    b = design.values[:, 1]
    expect_fail, expect_hang = np.flatnonzero(b < 0.10), np.flatnonzero((b >= 0.10) & (b < 0.12))
    # A Latin hypercube puts exactly 10 % and 2 % of 1000 rows in those strata of b.
    assert (expect_fail.size, expect_hang.size) == (100, 20)
    forcing = Forcing(3600.0, {"temp_air_out": np.linspace(0.0, 10.0, 48)})
    res = run_design(
        sims.Faulty(), forcing, design, cache_dir=tmp_path, backend="processes", jobs=2, timeout=2.0
    )
    failed = {f.index: f for f in res.failures}
    assert set(failed) == set(expect_fail) | set(expect_hang)
    assert {failed[i].error_type for i in expect_hang} == {"timeout"}
    assert all("diverged" in failed[i].message for i in expect_fail)
    assert res.indices.size == 880
    np.testing.assert_allclose(
        res.outputs["y"][0], sims.reference(*design.values[res.indices[0]], forcing)["y"]
    )
    html = _failures(res.failures)
    for i in failed:  # every failure is listed in the report's table
        assert f"<td>{i}</td>" in html
