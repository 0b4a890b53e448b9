"""The discrepancy phase's chains: batched eq. 19, a known target, length by convergence, resume."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bayescal.calibration.kron import make_algebra
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.calibration.priors import ThetaPriors
from bayescal.design import UniformPrior
from bayescal.discrepancy import estimate_discrepancy
from bayescal.discrepancy.batched import BatchedDelta, Segment
from bayescal.discrepancy.moments import GlsObservations
from bayescal.discrepancy.phase import DeltaPhase
from bayescal.discrepancy.sampler import (
    DeltaDraws,
    DeltaSettings,
    Whitening,
    checkpoint_file,
    run_delta_chains,
)
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.errors import ConfigError
from bayescal.mcmc.diagnostics import diagnose
from virtual_wall import VirtualExperiment


@pytest.fixture(scope="module")
def small(
    small_wall: tuple[VirtualExperiment, Assembled, Emulator],
) -> tuple[Assembled, Emulator, Posterior]:
    _, a, em = small_wall
    post = calibrate(em, a, n_chains=4, n_burn=50, n_draws=50, seed=1, backend="serial")
    return a, em, post


# --- eq. 19 for all chains at once against the scalar reference -------------------------


def test_batched_likelihood_equals_the_scalar_target_per_chain(
    small: tuple[Assembled, Emulator, Posterior],
) -> None:
    a, em, _ = small
    alg = make_algebra("kronecker", em.theta, em.x, em.kernels, em.basis.ktk, em.w, a.w_star)
    priors = list(a.priors.values())
    phase = DeltaPhase(em, a.y_star_std, alg, priors, em.lam, 40.0, 20)
    rng = np.random.default_rng(3)
    at = rng.uniform(0.2, 0.8, size=(3, 3))  # each chain's update point
    rngs = [np.random.default_rng(10 + b) for b in range(3)]
    gls = phase.observations(at, rngs)
    # The scalar targets from the same realisations (same generators, same order).
    refs = [phase.update(at[b], np.random.default_rng(10 + b)) for b in range(3)]
    grid = alg.stacked_grid()
    assert grid is not None
    batched = BatchedDelta(grid, phase.a)
    segment = batched.segment(np.stack([g.w_star for g in gls]), np.stack([g.nuggets for g in gls]))
    for _ in range(3):
        u = rng.random((3, 3))
        got = batched(u, segment) + np.array([g.extra for g in gls])
        got += np.array([ThetaPriors(tuple(priors)).scalar(row) for row in u])
        want = np.array([refs[b](u[b]) for b in range(3)])
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
    # One chain's rows give that chain's values.
    one = batched(u[1:2], segment.rows([1]))
    np.testing.assert_allclose(one, batched(u, segment)[1:2], rtol=1e-12)


# --- the sampler on a target with a known posterior -------------------------------------

MEAN = np.array([0.4, 0.6])
SD = np.array([0.05, 0.08])
CORR = 0.9
COV = np.array([[SD[0] ** 2, CORR * SD[0] * SD[1]], [CORR * SD[0] * SD[1], SD[1] ** 2]])


class GaussianPhase:
    """A stand-in :class:`DeltaPhase`: uniform priors, updates that change nothing."""

    theta_priors = ThetaPriors((UniformPrior(0.0, 1.0), UniformPrior(0.0, 1.0)))

    def __init__(self) -> None:
        self.calls = 0

    def observations(self, u: np.ndarray, rngs: list[np.random.Generator]) -> list[GlsObservations]:
        self.calls += 1
        for rng in rngs:  # consume randomness as the real update does
            rng.standard_normal(3)
        return [GlsObservations(np.zeros((1, 1)), np.ones((1, 1)), 0.0) for _ in rngs]


class GaussianLikelihood:
    """A stand-in :class:`BatchedDelta`: a correlated Gaussian in ``u`` (5 SDs inside [0, 1])."""

    def __init__(self) -> None:
        self.prec = np.linalg.inv(COV)

    def segment(self, w_star: np.ndarray, nuggets: np.ndarray) -> Segment:
        b = w_star.shape[0]
        return Segment(np.zeros((b, 1, 1)), np.ones((b, 1, 1, 1)))

    def __call__(self, u: np.ndarray, segment: Segment) -> np.ndarray:
        d = u - MEAN
        out: np.ndarray = -0.5 * np.einsum("bi,ij,bj->b", d, self.prec, d)
        return out


def _gaussian_run(seed: int, **kw: Any) -> DeltaDraws:
    settings = DeltaSettings(
        n_burn=int(kw.get("n_burn", 600)),
        n_draws=int(kw.get("n_draws", 1500)),
        max_draws=int(kw.get("max_draws", 6000)),
        update_interval=int(kw.get("update_interval", 40)),
    )
    starts = np.array([[0.3, 0.5], [0.5, 0.7], [0.35, 0.65], [0.45, 0.55]])
    # A poor initial whitening (independent, wrong scale): burn-in must fix it.
    whitening = Whitening(np.zeros(2), np.diag([1.0, 1.0]))
    return run_delta_chains(
        GaussianPhase(),  # type: ignore[arg-type]
        GaussianLikelihood(),  # type: ignore[arg-type]
        starts,
        whitening,
        settings,
        seed,
        names=["a", "b"],
        checkpoint=kw.get("checkpoint"),
        callback=kw.get("callback"),
    )


def test_chains_sample_a_known_posterior() -> None:
    res = _gaussian_run(7)
    draws = res.unit_draws
    assert res.converged
    diag = diagnose(draws, ["a", "b"])
    assert np.all(diag.rhat <= 1.01)
    assert np.all(diag.ess_bulk >= 400)
    flat = draws.reshape(-1, 2)
    # Tolerances from the Monte Carlo standard errors of the run itself (4 MCSE: a
    # false alarm about once in 16 000 runs per quantity).
    assert np.all(np.abs(flat.mean(axis=0) - MEAN) < 4.0 * diag.mcse_mean), (
        flat.mean(axis=0),
        diag.mcse_mean,
    )
    assert np.all(np.abs(flat.std(axis=0) - SD) < 4.0 * diag.mcse_sd), (
        flat.std(axis=0),
        diag.mcse_sd,
    )
    # The correlation: its MCSE from the ESS of the product of the standardised draws.
    z = (draws - MEAN) / SD
    prod = z[..., 0] * z[..., 1]
    ess = diagnose(prod[..., None], ["ab"]).ess_bulk[0]
    assert abs(prod.mean() - CORR) < 4.0 * prod.std() / np.sqrt(ess)
    # Whitened coordinates: acceptance near the 0.44 the widths were adapted to.
    assert np.all((res.acceptance > 0.3) & (res.acceptance < 0.6))


def test_chains_are_extended_until_converged_or_the_cap() -> None:
    short = _gaussian_run(3, n_burn=100, n_draws=50, max_draws=5000)
    n = short.unit_draws.shape[1]
    assert short.converged
    assert 50 < n <= 5000
    capped = _gaussian_run(3, n_burn=100, n_draws=50, max_draws=60)
    assert capped.unit_draws.shape[1] == 60
    assert not capped.converged


def test_bad_settings_raise() -> None:
    with pytest.raises(ConfigError, match="max_draws"):
        DeltaSettings(n_burn=0, n_draws=10, max_draws=5, update_interval=1)
    with pytest.raises(ConfigError, match="n_draws"):
        DeltaSettings(n_burn=0, n_draws=2, max_draws=5, update_interval=1)


class Interrupt(Exception):
    """Stands for a kill."""


@pytest.mark.parametrize("after", [3, 17])
def test_interrupted_chains_resume_identically(tmp_path: Path, after: int) -> None:
    kw: dict[str, Any] = {"n_burn": 100, "n_draws": 60, "max_draws": 400, "update_interval": 15}
    reference = _gaussian_run(11, **kw)
    ticks = 0

    def kill(_: int) -> None:
        nonlocal ticks
        ticks += 1
        if ticks == after:
            raise Interrupt

    with pytest.raises(Interrupt):
        _gaussian_run(11, checkpoint=checkpoint_file(tmp_path, 0.0), callback=kill, **kw)
    assert (tmp_path / "delta.npz").exists()
    resumed = _gaussian_run(11, checkpoint=checkpoint_file(tmp_path, 0.0), **kw)
    np.testing.assert_array_equal(resumed.unit_draws, reference.unit_draws)
    np.testing.assert_array_equal(resumed.log_density, reference.log_density)
    assert resumed.updates == reference.updates


def test_interrupted_phase_resumes_identically(
    small: tuple[Assembled, Emulator, Posterior], tmp_path: Path
) -> None:
    a, em, post = small
    kw: dict[str, Any] = {
        "realisations": 10,
        "update_interval": 7,
        "n_chains": 4,
        "n_burn": 20,
        "n_draws": 30,
    }
    reference = estimate_discrepancy(em, a, post, seed=4, **kw)
    count = 0

    def kill(_: int) -> None:
        nonlocal count
        count += 1
        if count == 4:
            raise Interrupt

    with pytest.raises(Interrupt):
        estimate_discrepancy(
            em,
            a,
            post,
            seed=4,
            checkpoint_dir=tmp_path,
            checkpoint_seconds=0.0,
            callback=kill,
            **kw,
        )
    resumed = estimate_discrepancy(
        em, a, post, seed=4, checkpoint_dir=tmp_path, checkpoint_seconds=0.0, **kw
    )
    np.testing.assert_array_equal(resumed.posterior.unit_draws, reference.posterior.unit_draws)
    np.testing.assert_array_equal(resumed.delta, reference.delta)
