"""The in-likelihood discrepancy conditioned on the training residuals, against dense Gaussians.

Every route (:mod:`bayescal.calibration.conditional`) is checked against the
joint Gaussian of the raw quantities written out in full: the simulator runs'
weights, every measured *sample* (white or AR(1) errors in sample space, so the
reduction to generalised least-squares weights is checked too) and the
predicted weights, conditioned by one dense solve.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from bayescal.calibration.conditional import OutputDiscrepancy, krige_observed
from bayescal.emulator.dense import grid_inputs
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import ObservationModel, OutputNoise

REL = 1e-10


def _ar1_corr(n: int, phi: float) -> np.ndarray:
    i = np.arange(n)
    return phi ** np.abs(i[:, None] - i[None, :])


def _condition(cov: np.ndarray, observed: np.ndarray, values: np.ndarray, targets: slice):
    """Mean and covariance of the target block given the observed indices (zero prior mean)."""
    idx = np.arange(cov.shape[0])
    obs, tgt = idx[observed], idx[targets]
    c_oo = cov[np.ix_(obs, obs)]
    c_to = cov[np.ix_(tgt, obs)]
    gain = np.linalg.solve(c_oo, c_to.T).T
    return gain @ values, cov[np.ix_(tgt, tgt)] - gain @ c_to.T


def _assert_same(
    mean: np.ndarray, cov: np.ndarray, ref_mean: np.ndarray, ref_cov: np.ndarray
) -> None:
    """Means ``(P, p)`` and per-period covariances ``(P, p, p)`` against the dense
    ``(P p,)`` mean and ``(P p, P p)`` covariance (period-major), to ~1e-10."""
    p = mean.shape[1]
    ref_mean = ref_mean.reshape(-1, p)
    np.testing.assert_allclose(mean, ref_mean, rtol=0, atol=REL * np.abs(ref_mean).max())
    for a in range(mean.shape[0]):
        ref = ref_cov[a * p : (a + 1) * p, a * p : (a + 1) * p]
        np.testing.assert_allclose(cov[a], ref, rtol=0, atol=REL * np.abs(ref).max())


def _model(
    em: Emulator, rng: np.random.Generator, error: str, kind: Any = True
) -> ObservationModel:
    k = np.asarray(em.basis.k, dtype=float)
    noise = OutputNoise("heat_flux_in", (0, k.shape[0]), tuple(range(k.shape[1])), error,  # type: ignore[arg-type]
                        discrepancy=kind)  # fmt: skip
    return ObservationModel((noise,), k, rng.normal(size=(k.shape[0], em.x.shape[0])))


def _problem(
    em: Emulator, seed: int, error: str, kind: Any = True
) -> tuple[np.random.Generator, ObservationModel]:
    """A generator and an observation model of random data on the emulator's periods."""
    rng = np.random.default_rng(seed)
    return rng, _model(em, rng, error, kind)


def test_emulator_weight_covariance_is_the_dense_gp_conditional(
    small_wall: tuple[Any, Any, Emulator],
) -> None:
    _, _, em = small_wall
    rng = np.random.default_rng(3)
    theta = rng.random(em.theta.shape[1])
    x_new = np.vstack([em.x, rng.random((3, em.x.shape[1])) * 1.2 - 0.1])
    z_sim = grid_inputs(em.theta, em.x)
    z_new = np.hstack([np.tile(theta, (x_new.shape[0], 1)), x_new])
    cov = em.weight_covariance(theta, x_new)
    mean, var = em.predict_weights(np.broadcast_to(theta, (x_new.shape[0], theta.size)), x_new)
    for j, kern in enumerate(em.kernels):
        c_ss = kern.full(z_sim) + em.nuggets[j] * np.eye(z_sim.shape[0])
        c_ns = kern.full(z_new, z_sim)
        ref = kern.full(z_new) - c_ns @ np.linalg.solve(c_ss, c_ns.T)
        np.testing.assert_allclose(cov[j], ref, rtol=0, atol=REL * np.abs(ref).max())
        np.testing.assert_allclose(np.diagonal(cov[j]), var[:, j], rtol=1e-9)
        ref_mean = c_ns @ np.linalg.solve(c_ss, em.w[:, j])
        np.testing.assert_allclose(mean[:, j], ref_mean, rtol=0, atol=1e-9)


@pytest.mark.parametrize(("error", "phi"), [("white", 0.0), ("ar1", 0.7)])
def test_emulator_route_equals_dense_conditioning_on_runs_and_samples(
    small_wall: tuple[Any, Any, Emulator], error: str, phi: float
) -> None:
    # z = eta(theta*, x) + delta(x) at training and new periods, given the runs'
    # weights W and every measured sample y* = K (eta + delta) + e.
    _, _, em = small_wall
    rng, obs = _problem(em, 11, error)
    k, (n, p), m = obs.k, obs.k.shape, em.x.shape[0]
    theta = rng.random(em.theta.shape[1])
    x_new = rng.random((2, em.x.shape[1]))
    x_all = np.vstack([em.x, x_new])
    lam_star, r = 40.0, 0.3
    values = {"lambda_star": lam_star, "phi": phi, "delta_rel": r}

    # bayescal's route
    model = OutputDiscrepancy.build(em, obs, 0, x_new)
    mean_w, _ = em.predict_weights(np.broadcast_to(theta, (x_all.shape[0], theta.size)), x_all)
    eta_cov = em.weight_covariance(theta, x_all)
    shift, cov = model.condition(values, mean_w[:m], eta_cov)
    got_mean = mean_w[m:] + shift

    # dense: [W_0, W_1, ..., y* (period-major), z (new period-major, basis-minor)]
    z_sim = grid_inputs(em.theta, em.x)
    z_all = np.hstack([np.tile(theta, (x_all.shape[0], 1)), x_all])
    n_sim = z_sim.shape[0]
    dim = p * n_sim + n * m + p * x_new.shape[0]
    full = np.zeros((dim, dim))
    ys = slice(p * n_sim, p * n_sim + n * m)
    zs = slice(p * n_sim + n * m, dim)
    blocks = []
    for j, kern in enumerate(em.kernels):
        # latent f_j + delta_j over the training and new periods (M of them)
        c_zz = kern.full(z_all) + r * kern.variance * kern.x_corr(x_all)
        c_sz = kern.full(z_sim, z_all)
        rows = slice(j * n_sim, (j + 1) * n_sim)
        full[rows, rows] = kern.full(z_sim) + em.nuggets[j] * np.eye(n_sim)
        # maps from the latent (M,) to y* (n m, period-major) and to z (P p, basis-minor)
        to_y = np.kron(np.eye(m, x_all.shape[0]), k[:, j][:, None])
        to_z = np.zeros((p * x_new.shape[0], x_all.shape[0]))
        to_z[np.arange(x_new.shape[0]) * p + j, m + np.arange(x_new.shape[0])] = 1.0
        blocks.append((rows, c_zz, c_sz, to_y, to_z))
    for rows, c_zz, c_sz, to_y, to_z in blocks:
        full[rows, ys] = c_sz @ to_y.T
        full[rows, zs] = c_sz @ to_z.T
        full[ys, ys] += to_y @ c_zz @ to_y.T
        full[ys, zs] += to_y @ c_zz @ to_z.T
        full[zs, zs] += to_z @ c_zz @ to_z.T
    full[ys, ys] += np.kron(np.eye(m), _ar1_corr(n, phi) / lam_star)
    full = np.triu(full) + np.triu(full, 1).T
    observed = np.zeros(dim, dtype=bool)
    observed[: p * n_sim + n * m] = True
    data = np.concatenate([em.w[:, j] for j in range(p)] + [obs.y_star.T.reshape(-1)])
    ref_mean, ref_cov = _condition(full, observed, data, zs)
    _assert_same(got_mean, cov, ref_mean, ref_cov)
    # conditioning moved something (the test can fail)
    assert np.abs(shift).max() > 1e-3


@pytest.mark.parametrize(
    ("error", "phi", "kind"),
    [
        ("white", 0.0, True),
        ("ar1", -0.4, True),
        ("ar1", 0.9, True),
        ("white", 0.0, "independent"),
        ("ar1", 0.6, "independent"),
        ("white", 0.0, "both"),
        ("ar1", 0.9, "both"),
    ],
)
def test_simulator_route_equals_dense_kriging_of_the_sample_residuals(
    small_wall: tuple[Any, Any, Emulator], error: str, phi: float, kind: Any
) -> None:
    # y* - y_sim = K delta + e with the simulator's output known exactly at theta*.
    # delta = a GP over the conditions (r c_x), a part independent between periods
    # (r0 times 1 for the same period, 0 otherwise), or their sum.
    _, _, em = small_wall
    rng, obs = _problem(em, 5, error, kind)
    k, (n, p), m = obs.k, obs.k.shape, em.x.shape[0]
    x_new = np.vstack([em.x[:2], rng.random((3, em.x.shape[1]))])  # two training periods again
    x_all = np.vstack([em.x, x_new])
    y_sim = rng.normal(size=(n, m))
    lam_star, r, r0 = 12.0, 0.05, 0.03
    over_x, independent = kind in (True, "both"), kind in ("independent", "both")
    values = {"lambda_star": lam_star, "phi": phi, "delta_rel": r, "delta_ind": r0}
    model = OutputDiscrepancy.build(em, obs, 0, x_new)
    shift, cov = model.condition(values, obs.weights_of(0, y_sim, phi))

    # dense, in sample space
    n_new = x_new.shape[0]
    c_delta = np.zeros((p * x_all.shape[0], p * x_all.shape[0]))  # basis-major
    big = x_all.shape[0]
    same = np.zeros((big, big))
    same[np.arange(big), np.arange(big)] = 1.0
    for a in range(2):  # the predicted copies of training periods 0 and 1
        same[a, m + a] = same[m + a, a] = 1.0
    for j, kern in enumerate(em.kernels):
        c_delta[j * big : (j + 1) * big, j * big : (j + 1) * big] = kern.variance * (
            over_x * r * kern.x_corr(x_all) + independent * r0 * same
        )
    to_y = np.zeros((n * m, p * big))
    for j in range(p):
        to_y[:, j * big : j * big + m] = np.kron(np.eye(m), k[:, j][:, None])
    to_z = np.zeros((n_new * p, p * big))
    for a in range(n_new):
        for j in range(p):
            to_z[a * p + j, j * big + m + a] = 1.0
    c_yy = to_y @ c_delta @ to_y.T + np.kron(np.eye(m), _ar1_corr(n, phi) / lam_star)
    c_zy = to_z @ c_delta @ to_y.T
    resid = (obs.y_star - y_sim).T.reshape(-1)
    ref_mean = c_zy @ np.linalg.solve(c_yy, resid)
    ref_cov = to_z @ c_delta @ to_z.T - c_zy @ np.linalg.solve(c_yy, c_zy.T)
    _assert_same(shift, cov, ref_mean, ref_cov)
    # the copies of training periods carry their residual over (the test can fail)
    assert np.abs(shift[:2]).max() > 1e-3
    # far from every training period the discrepancy is back at its prior
    far = OutputDiscrepancy.build(em, obs, 0, np.full((1, em.x.shape[1]), 50.0))
    shift_far, cov_far = far.condition(values, obs.weights_of(0, y_sim, phi))
    np.testing.assert_allclose(shift_far, 0.0, atol=1e-12)
    prior = over_x * r + independent * r0
    np.testing.assert_allclose(np.diagonal(cov_far[0]), prior * np.array(
        [kern.variance for kern in em.kernels]), rtol=1e-12)  # fmt: skip


def test_krige_observed_checks_its_shapes() -> None:
    with pytest.raises(ValueError, match="does not fit"):
        krige_observed(np.zeros((3, 2)), np.zeros((2, 2, 2)), np.eye(2))
    with pytest.raises(ValueError, match="noise block"):
        krige_observed(np.zeros((3, 2)), np.zeros((2, 5, 5)), np.eye(3))


@pytest.mark.parametrize(
    ("error", "phi", "kind"),
    [("white", 0.0, True), ("ar1", 0.6, True), ("white", 0.0, "both")],
)
def test_noise_given_the_simulator_is_the_dense_conditional_of_lambda_star(
    small_wall: tuple[Any, Any, Emulator], error: str, phi: float, kind: Any
) -> None:
    """E[1/lambda*] given the run at a draw, phi and r: the generalised eigenproblem of
    the observed weights plus what the basis leaves, against the density of every
    measured sample (AR(1) or white in sample space) under K delta + e, integrated over
    log lambda* on a dense grid."""
    from scipy import stats

    _, _, em = small_wall
    rng, obs = _problem(em, 8, error, kind)
    k, (n, p), m = obs.k, obs.k.shape, em.x.shape[0]
    y_sim = rng.normal(size=(n, m))
    r, r0 = 0.05, 0.03
    values = {"lambda_star": 1.0, "phi": phi, "delta_rel": r, "delta_ind": r0}
    field = OutputDiscrepancy.build(em, obs, 0, np.zeros((0, em.x.shape[1])))
    resid = obs.y_star - y_sim
    outside = obs.precision_out_of_basis(0, resid, phi)
    got = field.noise_given(values, obs.weights_of(0, y_sim, phi), outside)

    over_x, independent = kind in (True, "both"), kind in ("independent", "both")
    c_delta = np.zeros((p * m, p * m))
    for j, kern in enumerate(em.kernels):
        c_delta[j * m : (j + 1) * m, j * m : (j + 1) * m] = kern.variance * (
            over_x * r * kern.x_corr(em.x) + independent * r0 * np.eye(m)
        )
    to_y = np.zeros((n * m, p * m))
    for j in range(p):
        to_y[:, j * m : (j + 1) * m] = np.kron(np.eye(m), k[:, j][:, None])
    signal = to_y @ c_delta @ to_y.T
    corr = np.kron(np.eye(m), _ar1_corr(n, phi))
    flat = resid.T.reshape(-1)
    a, b = obs.outputs[0].prior

    def log_post(ell: float) -> float:
        lam = np.exp(ell)
        dense = stats.multivariate_normal(np.zeros(flat.size), signal + corr / lam)
        return float(a * ell - b * lam + dense.logpdf(flat))

    centre = np.log(1.0 / got)  # near the mode of log(1/lambda*)
    grid = -centre + np.linspace(-1.0, 1.0, 81)
    logs = np.array([log_post(g) for g in grid])
    top = int(np.argmax(logs))
    assert 10 < top < 70  # the grid holds the mode
    w = np.exp(logs - logs.max())
    assert w[0] < 1e-12  # and the tails
    assert w[-1] < 1e-12
    ref = float(np.trapezoid(w, grid) / np.trapezoid(w * np.exp(-grid), grid))
    assert got == pytest.approx(ref, rel=1e-6)
    # the in-basis part matters here: the noise it implies is not the outside one alone
    assert abs(got / ((outside[0] - 1.0) / outside[1]) - 1.0) > 1e-3


@pytest.mark.parametrize("kind", [True, "orthogonal"])
def test_noise_given_a_negligible_discrepancy_is_the_white_update_of_the_whole_residual(
    small_wall: tuple[Any, Any, Emulator], kind: Any
) -> None:
    """At r -> 0 the residuals' weights are noise as well: the conditional is the Gamma
    update by every sample's residual (the orthogonal discrepancy's constrained prior
    included)."""
    _, _, em = small_wall
    rng, obs = _problem(em, 9, "white", kind)
    y_sim = rng.normal(size=obs.y_star.shape)
    values = {"lambda": 50.0, "lambda_star": 1.0, "delta_rel": 1e-14}
    field = OutputDiscrepancy.build(em, obs, 0, np.zeros((0, em.x.shape[1])))
    resid = obs.y_star - y_sim
    outside = obs.precision_out_of_basis(0, resid)
    theta = np.full(em.theta.shape[1], 0.5)
    got = field.noise_given(values, obs.weights_of(0, y_sim), outside, theta)
    shape, rate = obs.precision_given(0, resid)
    assert got == pytest.approx((shape - 1.0) / rate, rel=1e-6)
