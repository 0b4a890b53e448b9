"""Observation error models (white, AR(1)) of eq. 16 against dense references.

Two references, independent of the fast algebra:

* the dense covariance of ``[w_j; w*_j]`` over all bases, with the noise of a
  group's observed weights coupled within each period, factorised by Cholesky;
* the density of the raw data, ``log p(W_sim, Y*)`` from the full joint Gaussian of
  the simulator weights and every measured sample (``Y* = K W* + e``, ``e`` white
  or AR(1)), which checks the whole factorisation of
  :mod:`bayescal.emulator.noise` (generalised least-squares weights plus the
  remainder), not only the algebra.

Agreement is asked to 1e-10 relative: both sides are exact; what separates them
is rounding in factorisations of matrices of a few hundred rows.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from scipy import linalg, stats

from bayescal.calibration import kron as kron_module
from bayescal.calibration.dense import DenseCalibrationDensity
from bayescal.calibration.kron import KronCalibrationDensity
from bayescal.calibration.target import CalibrationPosterior
from bayescal.design import UniformPrior
from bayescal.emulator.assemble import Assembled, NoiseSpec, assemble
from bayescal.emulator.dense import gaussian_logdensity, grid_inputs
from bayescal.emulator.kernel import SeparableKernel
from bayescal.emulator.noise import (
    ObservationModel,
    OutputNoise,
    ar1_whiten,
    noise_prior_from_sd,
)
from bayescal.errors import ConfigError

REL = 1e-10


def _problem(seed: int, n_runs: int = 6, n_per: int = 5, t: int = 2, s: int = 1, p: int = 3):
    rng = np.random.default_rng(seed)
    kernels = [
        SeparableKernel(rng.uniform(0.2, 0.95, t + s), float(rng.uniform(0.5, 3.0)), t)
        for _ in range(p)
    ]
    return rng, kernels, rng.random((n_runs, t)), rng.random((n_per, s))


def _dense_grouped(theta, x, kernels, a, a_star, w, w_star, theta_star, groups):
    """The dense covariance of all bases' [w_j; w*_j] with coupled observation noise."""
    n_runs, n_per = theta.shape[0], x.shape[0]
    z = grid_inputs(theta, x)
    z_obs = np.hstack([np.tile(theta_star, (n_per, 1)), x])
    zz = np.vstack([z, z_obs])
    block = n_runs * n_per + n_per
    p = len(kernels)
    cov = np.zeros((p * block, p * block))
    vec = np.empty(p * block)
    for j, k in enumerate(kernels):
        rows = slice(j * block, (j + 1) * block)
        c = k.full(zz)
        c[np.diag_indices(n_runs * n_per)] += a[j]
        cov[rows, rows] = c
        vec[rows] = np.concatenate([w[:, j], w_star[:, j]])
    grouped = {j for members, _ in groups for j in members}
    for j in range(p):
        if j not in grouped:
            start = j * block + n_runs * n_per
            idx = np.arange(start, start + n_per)
            cov[idx, idx] += a_star[j]
    for members, noise in groups:
        for aj, j in enumerate(members):
            for ak, k in enumerate(members):
                oj = j * block + n_runs * n_per + np.arange(n_per)
                ok = k * block + n_runs * n_per + np.arange(n_per)
                cov[oj, ok] += noise[aj, ak]
    return gaussian_logdensity(cov, vec)


@pytest.mark.parametrize("seed", range(4))
def test_grouped_noise_equals_the_dense_covariance(seed: int) -> None:
    rng, kernels, theta, x = _problem(seed)
    p = len(kernels)
    w = rng.normal(size=(theta.shape[0] * x.shape[0], p))
    w_star = rng.normal(size=(x.shape[0], p))
    a = rng.uniform(0.01, 0.1, p)
    a_star = rng.uniform(0.01, 0.2, p)
    half = rng.normal(size=(2, 2))
    noise = half @ half.T * 0.05 + np.eye(2) * 0.01
    groups = [((0, 2), noise)]
    theta_star = rng.random(theta.shape[1])
    density = KronCalibrationDensity(theta, x, kernels, np.ones(p), w, w_star)
    fast = density.pieces_grouped(theta_star, a, a_star, groups)
    ref = _dense_grouped(theta, x, kernels, a, a_star, w, w_star, theta_star, groups)
    dense = DenseCalibrationDensity(theta, x, kernels, np.ones(p), w, w_star)
    assert dense.pieces_grouped(theta_star, a, a_star, groups).logpdf == pytest.approx(
        ref.logpdf, rel=REL
    )
    assert fast.size == ref.size
    assert fast.logpdf == pytest.approx(ref.logpdf, rel=REL)
    assert fast.logdet == pytest.approx(ref.logdet, rel=REL)
    assert fast.quad == pytest.approx(ref.quad, rel=REL)
    # No group: the per-basis route of eq. 14 with nuggets a*.
    plain = density.pieces_grouped(theta_star, a, a_star, [])
    assert plain.logpdf == pytest.approx(density.pieces_nuggets(theta_star, a, a_star).logpdf)


def _raw_density(theta, x, kernels, a, k, y_star, theta_star, noise_cov, w, extra=None):
    """log p(W_sim, Y*) from the joint Gaussian of the simulator weights and all samples
    (``extra``: more covariance of the samples, period-major)."""
    n_runs, n_per = theta.shape[0], x.shape[0]
    n, p = k.shape
    z = grid_inputs(theta, x)
    z_obs = np.hstack([np.tile(theta_star, (n_per, 1)), x])
    n_sim = n_runs * n_per
    dim = p * n_sim + n * n_per
    cov = np.zeros((dim, dim))
    vec = np.concatenate([w[:, j] for j in range(p)] + [y_star.T.reshape(-1)])
    ys = slice(p * n_sim, dim)
    for j, kern in enumerate(kernels):
        rows = slice(j * n_sim, (j + 1) * n_sim)
        c_sim = kern.full(z)
        c_sim[np.diag_indices(n_sim)] += a[j]
        cov[rows, rows] = c_sim
        cross = kern.full(z, z_obs)  # (n_sim, m*): sim weight j with observed weight j
        # y*_i (n samples, period-major in vec) = K w*_i + e_i
        cov[rows, ys] = np.kron(cross, k[:, j][None, :])
        c_obs = kern.full(z_obs)  # (m*, m*)
        cov[ys, ys] += np.kron(c_obs, np.outer(k[:, j], k[:, j]))
    cov[ys, ys] += np.kron(np.eye(n_per), noise_cov)
    if extra is not None:
        cov[ys, ys] += extra
    cov[ys, :] = cov[:, ys].T
    cov[ys, ys] = 0.5 * (cov[ys, ys] + cov[ys, ys].T)
    return gaussian_logdensity(cov, vec).logpdf


def _ar1_corr(n: int, phi: float) -> np.ndarray:
    i = np.arange(n)
    return phi ** np.abs(i[:, None] - i[None, :])


@pytest.mark.parametrize(("phi", "seed"), [(0.0, 0), (0.6, 1), (0.9, 2), (-0.3, 3)])
def test_ar1_factorisation_equals_the_raw_data_density(phi: float, seed: int) -> None:
    rng, kernels, theta, x = _problem(seed, n_runs=5, n_per=4, p=2)
    n = 9
    k = np.linalg.qr(rng.normal(size=(n, 2)))[0] * np.array([3.0, 1.5])  # orthogonal columns
    y_star = rng.normal(size=(n, x.shape[0]))
    w = rng.normal(size=(theta.shape[0] * x.shape[0], 2))
    a = rng.uniform(0.01, 0.1, 2)
    lam_star = 7.0
    theta_star = rng.random(theta.shape[1])
    model = ObservationModel(
        (OutputNoise("q", (0, n), (0, 1), "ar1" if phi else "white"),), k, y_star
    )
    pieces = model.gls(0, phi)
    density = KronCalibrationDensity(theta, x, kernels, np.einsum("ij,ij->j", k, k), w,
                                     pieces.w_hat)  # fmt: skip
    fast = density.pieces_grouped(theta_star, a, [1.0, 1.0], [((0, 1), pieces.h0_inv / lam_star)])
    total = fast.logpdf + model.remainder(0, pieces, lam_star)
    ref = _raw_density(theta, x, kernels, a, k, y_star, theta_star, _ar1_corr(n, phi) / lam_star, w)
    assert total == pytest.approx(ref, rel=REL)
    if phi == 0.0:  # white: per-basis nuggets and eq. 7's Gamma terms give the same
        white = density.pieces_nuggets(theta_star, a, model.white_nuggets([lam_star])).logpdf
        assert white == pytest.approx(fast.logpdf, rel=REL)


@pytest.mark.parametrize(
    ("kind", "phi", "seed"),
    [(True, 0.6, 0), ("independent", 0.6, 1), ("both", 0.9, 2), ("independent", -0.3, 3),
     ("both", 0.0, 4)],
)  # fmt: skip
def test_discrepancy_kinds_in_the_target_equal_the_raw_data_density(
    kind: Any, phi: float, seed: int
) -> None:
    # The calibration target's likelihood (eq. 16 with AR(1) errors, section 4a) with a
    # discrepancy over the conditions (r c_x), independent between periods (r0 per
    # period, none across) or both, against the joint Gaussian of the simulator
    # weights and every measured sample written out in full.
    rng, kernels, theta, x = _problem(seed, n_runs=5, n_per=4, p=2)
    n = 9
    k = np.linalg.qr(rng.normal(size=(n, 2)))[0] * np.array([3.0, 1.5])  # orthogonal columns
    y_star = rng.normal(size=(n, x.shape[0]))
    w = rng.normal(size=(theta.shape[0] * x.shape[0], 2))
    lam, lam_star, r, r0 = 40.0, 7.0, 0.08, 0.3
    model = ObservationModel(
        (OutputNoise("q", (0, n), (0, 1), "ar1", discrepancy=kind),), k, y_star
    )
    ktk = np.einsum("ij,ij->j", k, k)
    density = KronCalibrationDensity(theta, x, kernels, ktk, w, model.ls_weights())
    priors = [UniformPrior(0.0, 1.0)] * theta.shape[1]
    target = CalibrationPosterior(density, priors, (5.0, 5.0), observations=model)
    theta_star = rng.random(theta.shape[1])
    rel = {"delta_rel": r, "delta_ind": r0}
    v = np.array([*theta_star, lam, lam_star, phi, *(rel[c] for c, _ in model.delta_coordinates)])
    over_x, independent = kind in (True, "both"), kind in ("independent", "both")
    assert len(model.delta_coordinates) == over_x + independent
    # dense: the discrepancy on basis j adds (r/tau_j c_x + r0/tau_j I) (x) k_j k_j^T
    extra = np.zeros((n * x.shape[0], n * x.shape[0]))
    for j, kern in enumerate(kernels):
        corr = over_x * r * kern.x_corr(x) + independent * r0 * np.eye(x.shape[0])
        extra += np.kron(kern.variance * corr, np.outer(k[:, j], k[:, j]))
    a = 1.0 / (lam * ktk)
    ref = _raw_density(theta, x, kernels, a, k, y_star, theta_star, _ar1_corr(n, phi) / lam_star, w,
                       extra)  # fmt: skip
    got = target(v) - target.log_prior(v)
    assert got == pytest.approx(ref, rel=REL)
    if phi == 0.0:  # a white output: the independent part joins the per-basis nuggets
        white = ObservationModel(
            (OutputNoise("q", (0, n), (0, 1), "white", discrepancy=kind),), k, y_star
        )
        target_w = CalibrationPosterior(density, priors, (5.0, 5.0), observations=white)
        v_w = np.delete(v, theta.shape[1] + 2)  # no phi
        in_basis = target_w(v_w) - target_w.log_prior(v_w)  # eq. 7 holds the remainder
        remainder = model.remainder(0, model.gls(0, 0.0), lam_star)
        assert in_basis == pytest.approx(got - remainder, rel=REL)
    # the discrepancy changed the density (the test can fail)
    plain = _raw_density(
        theta, x, kernels, a, k, y_star, theta_star, _ar1_corr(n, phi) / lam_star, w
    )
    assert got != pytest.approx(plain, rel=1e-6)


def test_with_observations_reuses_the_grid_and_agrees_with_a_rebuild() -> None:
    rng, kernels, theta, x = _problem(7)
    p = len(kernels)
    w = rng.normal(size=(theta.shape[0] * x.shape[0], p))
    first, second = rng.normal(size=(x.shape[0], p)), rng.normal(size=(x.shape[0], p))
    density = KronCalibrationDensity(theta, x, kernels, np.ones(p), w, first)
    moved = density.with_observations(second)
    rebuilt = KronCalibrationDensity(theta, x, kernels, np.ones(p), w, second)
    ts = rng.random(theta.shape[1])
    assert moved.logpdf(ts, 2.0, 3.0) == rebuilt.logpdf(ts, 2.0, 3.0)
    assert moved.logpdf(ts, 2.0, 3.0) != density.logpdf(ts, 2.0, 3.0)
    assert density.stacked_grid().bases[0].eig_x is moved.stacked_grid().bases[0].eig_x


def test_with_observations_shares_the_memos_that_do_not_depend_on_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A new ``w*`` (an AR(1) coefficient's move) recomputes no simulator block, and the
    shared memos give the values of a density built afresh, both ways."""
    rng, kernels, theta, x = _problem(8)
    p = len(kernels)
    w = rng.normal(size=(theta.shape[0] * x.shape[0], p))
    first, second = rng.normal(size=(x.shape[0], p)), rng.normal(size=(x.shape[0], p))
    density = KronCalibrationDensity(theta, x, kernels, np.ones(p), w, first)
    real = kron_module._sim_block
    calls: list[float] = []

    def counted(cache: Any, a: float) -> Any:
        calls.append(a)
        return real(cache, a)

    monkeypatch.setattr(kron_module, "_sim_block", counted)
    root = rng.normal(size=(p, p))
    groups = [(tuple(range(p)), root @ root.T / p + 0.1 * np.eye(p))]
    ts, a = rng.random(theta.shape[1]), rng.uniform(0.01, 0.1, p)
    before = density.pieces_grouped(ts, a, np.ones(p), groups).logpdf
    n_blocks = len(calls)
    moved = density.with_observations(second)
    after = moved.pieces_grouped(ts, a, np.ones(p), groups).logpdf
    assert len(calls) == n_blocks == p
    rebuilt = KronCalibrationDensity(theta, x, kernels, np.ones(p), w, second)
    assert after == rebuilt.pieces_grouped(ts, a, np.ones(p), groups).logpdf
    assert density.pieces_grouped(ts, a, np.ones(p), groups).logpdf == before != after


def test_prewhitening_gives_the_ar1_quadratic_form() -> None:
    rng = np.random.default_rng(3)
    y = rng.normal(size=(11, 3))
    for phi in (0.0, 0.5, -0.8, 0.99):
        z = ar1_whiten(y, phi)
        exact = y.T @ np.linalg.solve(_ar1_corr(11, phi), y)
        np.testing.assert_allclose(z.T @ z, exact, rtol=1e-9, atol=1e-9)
        sign, logdet = np.linalg.slogdet(_ar1_corr(11, phi))
        assert sign > 0
        assert 10 * math.log1p(-phi * phi) == pytest.approx(logdet, abs=1e-9)


def test_white_prior_is_eq_7_per_output() -> None:
    rng = np.random.default_rng(4)
    k = linalg.block_diag(rng.normal(size=(6, 2)), rng.normal(size=(5, 1)))
    y = rng.normal(size=(11, 8))
    model = ObservationModel(
        (
            OutputNoise("a", (0, 6), (0, 1), prior=(1.0, 2.0)),
            OutputNoise("b", (6, 11), (2,), prior=(0.5, 1e-6)),
        ),
        k,
        y,
    )
    for q, (rows, cols) in enumerate(((slice(0, 6), [0, 1]), (slice(6, 11), [2]))):
        kq, yq = k[rows][:, cols], y[rows]
        resid = yq - kq @ np.linalg.lstsq(kq, yq, rcond=None)[0]
        shape, rate = model.outputs[q].prior
        want = (shape + 0.5 * 8 * (kq.shape[0] - kq.shape[1]), rate + 0.5 * np.sum(resid**2))
        assert model.white_prior(q) == pytest.approx(want, rel=1e-12)
    assert model.names() == ("lambda_star_a", "lambda_star_b")
    assert model.white_nuggets([2.0, 4.0]) == pytest.approx(
        1.0 / (np.einsum("ij,ij->j", k, k) * np.array([2.0, 2.0, 4.0]))
    )
    with pytest.raises(Exception, match="reach rows of another output"):
        ObservationModel((OutputNoise("a", (0, 6), (0, 1, 2)),), k, y)


def test_noise_prior_from_a_sensor_accuracy() -> None:
    shape, rate = noise_prior_from_sd(0.1, scale=2.0)
    # centred: the prior mean of lambda* is (s / sd)^2
    assert shape / rate == pytest.approx((2.0 / 0.1) ** 2)
    shape, rate = noise_prior_from_sd([0.05, 0.3], scale=2.0)
    lam = stats.gamma(shape, scale=1.0 / rate)
    sd_975, sd_025 = 2.0 / np.sqrt(lam.ppf([0.025, 0.975]))
    assert (sd_025, sd_975) == pytest.approx((0.05, 0.3), rel=1e-8)
    for bad in (0.0, -1.0, [0.3, 0.05], [0.1, 0.2, 0.3], float("nan")):
        with pytest.raises(ConfigError, match="noise sd"):
            noise_prior_from_sd(bad, scale=1.0)  # type: ignore[arg-type]


@pytest.mark.parametrize("seed", range(3))
def test_discrepancy_variance_agrees_with_the_dense_covariance(seed: int) -> None:
    # delta_j c_x(x, x') more covariance on the observed weights: a model discrepancy
    # GP over the periods' conditions. Every Kronecker route against the dense one.
    rng, kernels, theta, x = _problem(seed)
    p = len(kernels)
    w = rng.normal(size=(theta.shape[0] * x.shape[0], p))
    w_star = rng.normal(size=(x.shape[0], p))
    a, a_star = rng.uniform(0.01, 0.1, p), rng.uniform(0.01, 0.2, p)
    delta = rng.uniform(0.0, 0.5, p)
    ts = rng.random(theta.shape[1])
    kron = KronCalibrationDensity(theta, x, kernels, np.ones(p), w, w_star)
    dense = DenseCalibrationDensity(theta, x, kernels, np.ones(p), w, w_star)
    ref = dense.pieces_nuggets(ts, a, a_star, delta).logpdf
    assert kron.pieces_nuggets(ts, a, a_star, delta).logpdf == pytest.approx(ref, rel=REL)
    per_period = np.repeat(a_star[:, None], x.shape[0], axis=1)  # the general Schur route
    assert kron.pieces_nuggets(ts, a, per_period, delta).logpdf == pytest.approx(ref, rel=REL)
    assert kron.pieces_grouped(ts, a, a_star, [], delta).logpdf == pytest.approx(ref, rel=REL)
    half = rng.normal(size=(2, 2))
    groups = [((0, 2), half @ half.T * 0.05 + np.eye(2) * 0.01)]
    assert kron.pieces_grouped(ts, a, a_star, groups, delta).logpdf == pytest.approx(
        dense.pieces_grouped(ts, a, a_star, groups, delta).logpdf, rel=REL
    )
    # The discrepancy changes the density (the test can fail).
    assert kron.pieces_nuggets(ts, a, a_star).logpdf != pytest.approx(ref, rel=1e-6)


def test_assemble_carries_each_outputs_error_model(
    small_wall: tuple[Any, Assembled, Any],
) -> None:
    ve, _, _ = small_wall
    a = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, variance=0.99, history=1,
        scale="output", noise={"heat_flux_in": NoiseSpec("ar1", 0.1, discrepancy=True)},
    )  # fmt: skip
    (o,) = a.observations.outputs
    assert (o.model, o.discrepancy, o.unit) == ("ar1", "conditions", "W/m²")
    assert a.observations.names() == ("lambda_star", "phi", "delta_rel")
    # the stated accuracy is the prior's centre, in standardised units
    assert o.prior[0] / o.prior[1] == pytest.approx((o.scale / 0.1) ** 2)


@pytest.mark.parametrize("phi", [0.0, 0.3, 0.77, 0.95, -0.5])
def test_gls_from_lag_sums_equals_prewhitening(phi: float) -> None:
    """The GLS pieces from the lag sums equal those of prewhitened series (to rounding)."""
    rng = np.random.default_rng(11)
    n, p, m = 48, 5, 9
    k = rng.normal(size=(n, p))
    y = k @ rng.normal(size=(p, m)) + 0.3 * rng.normal(size=(n, m))
    model = ObservationModel((OutputNoise("q", (0, n), tuple(range(p)), "ar1"),), k, y)
    got = model.gls(0, phi)
    kz, yz = ar1_whiten(k, phi), ar1_whiten(y, phi)
    w = np.linalg.solve(kz.T @ kz, kz.T @ yz)
    resid = yz - kz @ w
    np.testing.assert_allclose(got.w_hat, w.T, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(got.h0_inv, np.linalg.inv(kz.T @ kz), rtol=1e-10, atol=1e-14)
    assert got.quad0 == pytest.approx(float(np.sum(resid * resid)), rel=1e-10)
    assert got.logdet_h0 == pytest.approx(np.linalg.slogdet(kz.T @ kz)[1], rel=1e-12)
    assert got.logdet_r == pytest.approx(np.linalg.slogdet(_ar1_corr(n, phi))[1], abs=1e-10)
