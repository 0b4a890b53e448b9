"""The orthogonal discrepancy (Plumlee 2017) against dense references.

Three references, independent of the Woodbury route of
:mod:`bayescal.calibration.orthogonal`:

* the dense covariance of all bases' ``[w_j; w*_j]`` with the constrained
  discrepancy ``Sigma - Sigma F (F^T Sigma F)^-1 F^T Sigma`` written in, by Cholesky;
* the density of the raw data (the simulator weights and every measured sample)
  with the constraint written in the samples' own space, ``C^T delta_y = 0`` for
  ``C`` the model's sensitivities of every measured sample (``K G``): this also
  checks that the weight-space constraint with ``k_j^T k_j`` is that one;
* finite differences of the dense emulator mean for the analytic gradient.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from bayescal.calibration.conditional import OutputDiscrepancy
from bayescal.calibration.dense import DenseCalibrationDensity
from bayescal.calibration.kron import KronCalibrationDensity
from bayescal.calibration.loo import loo_conditional
from bayescal.calibration.orthogonal import constrained_covariance, constraint_matrix
from bayescal.calibration.target import CalibrationPosterior
from bayescal.design import UniformPrior
from bayescal.emulator.dense import gaussian_logdensity, grid_inputs
from bayescal.emulator.kernel import SeparableKernel
from bayescal.emulator.noise import ObservationModel, OutputNoise

REL = 1e-10


def _problem(seed: int, runs: int = 7, periods: int = 6, p: int = 3, obs=None):
    rng = np.random.default_rng(seed)
    t, s = 2, 2
    kernels = [
        SeparableKernel(rng.uniform(0.3, 0.9, t + s), float(rng.uniform(0.5, 2.0)), t)
        for _ in range(p)
    ]
    theta, x = rng.random((runs, t)), rng.random((periods, s))
    w = rng.standard_normal((runs * periods, p))
    idx = np.arange(periods) if obs is None else np.asarray(obs)
    w_star = rng.standard_normal((idx.size, p))
    args = (theta, x, kernels, rng.uniform(0.5, 3.0, p), w, w_star, idx)
    return KronCalibrationDensity(*args), DenseCalibrationDensity(*args), rng


def _dense_mean(dense: DenseCalibrationDensity, ts: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The emulator's mean of every basis at ``(theta*, x_O)`` ``(p, m_obs)``, densely."""
    d = dense.data
    z = grid_inputs(d.theta, d.x)
    x_obs = d.x[d.obs_index]
    z_obs = np.hstack([np.tile(ts, (x_obs.shape[0], 1)), x_obs])
    out = []
    for j, kern in enumerate(d.kernels):
        cov = kern.full(z) + a[j] * np.eye(z.shape[0])
        out.append(kern.full(z_obs, z) @ np.linalg.solve(cov, d.w[:, j]))
    return np.array(out)


@pytest.mark.parametrize("obs", [None, [0, 2, 3, 5], [5, 1, 0, 2, 3, 4]])
def test_the_gradient_is_that_of_the_emulator_mean(obs) -> None:
    fast, dense, rng = _problem(0, obs=obs)
    ts, a = rng.random(2), rng.uniform(0.01, 0.1, 3)
    got = fast.mean_gradient(ts, a)
    assert got == pytest.approx(dense.mean_gradient(ts, a), abs=1e-10)
    step = 1e-6
    for k in range(2):
        e = np.eye(2)[k] * step
        fd = (_dense_mean(dense, ts + e, a) - _dense_mean(dense, ts - e, a)) / (2 * step)
        assert got[:, :, k] == pytest.approx(fd, abs=1e-6)


@pytest.mark.parametrize(
    ("seed", "obs"), [(0, None), (1, [0, 2, 3, 5]), (2, [5, 1, 0, 2, 3, 4]), (3, None)]
)
def test_fast_route_equals_the_dense_reference(seed: int, obs) -> None:
    fast, dense, rng = _problem(seed, obs=obs)
    ts, a = rng.random(2), rng.uniform(0.01, 0.1, 3)
    f = constraint_matrix(fast.mean_gradient(ts, a), fast.data.ktk, [(0, 1), (2,)])
    delta, a_star = rng.uniform(0.05, 1.0, 3), rng.uniform(0.05, 0.2, 3)
    got = fast.pieces_nuggets(ts, a, a_star, delta, f).logpdf
    assert got == pytest.approx(dense.pieces_nuggets(ts, a, a_star, delta, f).logpdf, rel=REL)
    # the constraint changed the density (the test can fail)
    assert got != pytest.approx(fast.pieces_nuggets(ts, a, a_star, delta).logpdf, rel=1e-6)
    per = rng.uniform(0.05, 0.2, (3, fast.data.obs_index.size))  # per-period nuggets
    got = fast.pieces_nuggets(ts, a, per, delta, f).logpdf
    assert got == pytest.approx(dense.pieces_nuggets(ts, a, per, delta, f).logpdf, rel=REL)
    groups = [((0, 1), np.array([[0.1, 0.03], [0.03, 0.2]]))]  # coupled noise (AR(1))
    got = fast.pieces_grouped(ts, a, a_star, groups, delta, f).logpdf
    ref = dense.pieces_grouped(ts, a, a_star, groups, delta, f).logpdf
    assert got == pytest.approx(ref, rel=REL)


def test_the_constrained_covariance_is_orthogonal_to_the_gradient() -> None:
    fast, _, rng = _problem(4)
    ts, a = rng.random(2), rng.uniform(0.01, 0.1, 3)
    f = constraint_matrix(fast.mean_gradient(ts, a), fast.data.ktk, [(0, 1, 2)])
    x = fast.data.x
    m = x.shape[0]
    x_new = rng.random((3, 2))
    x_all = np.vstack([x, x_new])
    blocks = [0.3 * k.x_corr(x_all) for k in fast.data.kernels]
    # rows basis-major over the training periods first, then the new ones
    order = [j * (m + 3) + i for j in range(3) for i in range(m)]
    order += [j * (m + 3) + m + i for j in range(3) for i in range(3)]
    sigma = linalg.block_diag(*blocks)[np.ix_(order, order)]
    perp = constrained_covariance(sigma, f.reshape(3 * m, -1))
    flat = f.reshape(3 * m, -1)
    assert np.abs(flat.T @ perp[: 3 * m]).max() < 1e-12 * np.abs(sigma).max()
    # a draw of the constrained discrepancy (training and new periods) meets the constraint
    vals, vecs = np.linalg.eigh(perp)
    draw = vecs @ (np.sqrt(np.clip(vals, 0.0, None)) * rng.standard_normal(vals.size))
    assert np.abs(flat.T @ draw[: 3 * m]).max() < 1e-10
    assert np.abs(draw).max() > 0.1  # not the zero field


def _raw(theta, x, kernels, a, k, y_star, theta_star, noise_cov, w, extra):
    """log p(W_sim, Y*) from the joint Gaussian of the simulator weights and all samples."""
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
        cov[rows, rows] = kern.full(z) + a[j] * np.eye(n_sim)
        cov[rows, ys] = np.kron(kern.full(z, z_obs), k[:, j][None, :])
        cov[ys, ys] += np.kron(kern.full(z_obs), np.outer(k[:, j], k[:, j]))
    cov[ys, ys] += np.kron(np.eye(n_per), noise_cov) + extra
    cov[ys, :] = cov[:, ys].T
    cov[ys, ys] = 0.5 * (cov[ys, ys] + cov[ys, ys].T)
    return gaussian_logdensity(cov, vec).logpdf


@pytest.mark.parametrize(("phi", "seed"), [(0.0, 0), (0.7, 1)])
def test_the_target_equals_the_raw_data_density_with_the_constraint_on_the_samples(
    phi: float, seed: int
) -> None:
    # Two outputs: "a" (two bases) with the orthogonal discrepancy, "b" (one basis) with
    # today's over the conditions; the constraint written on a's measured samples.
    rng = np.random.default_rng(seed)
    t, runs, per, n1, n2 = 2, 5, 5, 7, 4
    kernels = [SeparableKernel(rng.uniform(0.3, 0.9, t + 1), float(rng.uniform(0.5, 2)), t)
               for _ in range(3)]  # fmt: skip
    theta, x = rng.random((runs, t)), rng.random((per, 1))
    k = np.zeros((n1 + n2, 3))
    k[:n1, :2] = np.linalg.qr(rng.normal(size=(n1, 2)))[0] * np.array([3.0, 1.5])
    k[n1:, 2] = rng.normal(size=n2)
    y_star = rng.normal(size=(n1 + n2, per))
    w = rng.normal(size=(runs * per, 3))
    model = ObservationModel(
        (
            OutputNoise("a", (0, n1), (0, 1), "ar1" if phi else "white", discrepancy="orthogonal"),
            OutputNoise("b", (n1, n1 + n2), (2,), "white", discrepancy=True),
        ),
        k,
        y_star,
    )
    ktk = np.einsum("ij,ij->j", k, k)
    priors = [UniformPrior(0.0, 1.0)] * t
    lam, lam_a, lam_b, r_a, r_b = 30.0, 6.0, 3.0, 0.2, 0.05
    theta_star = rng.random(t)
    v = [*theta_star, lam, lam_a, lam_b, *([phi] if phi else []), r_a, r_b]
    a = 1.0 / (lam * ktk)
    # the samples' discrepancy: a's constrained to C^T delta_a = 0, b's as today
    dense = DenseCalibrationDensity(theta, x, kernels, ktk, w, model.ls_weights())
    grad = dense.mean_gradient(theta_star, a)  # (3, per, t)
    ka = k[:n1, :2]
    sig_a = sum(
        np.kron(r_a * kernels[j].variance * kernels[j].x_corr(x), np.outer(ka[:, j], ka[:, j]))
        for j in range(2)
    )
    c = np.vstack([ka @ grad[:2, i, :] for i in range(per)])  # (per n1, t): period-major
    sig_a = constrained_covariance(sig_a, c)
    sig_b = np.kron(
        r_b * kernels[2].variance * kernels[2].x_corr(x), np.outer(k[n1:, 2], k[n1:, 2])
    )
    extra = np.zeros((per * (n1 + n2),) * 2)
    rows_a = np.concatenate([i * (n1 + n2) + np.arange(n1) for i in range(per)])
    rows_b = np.concatenate([i * (n1 + n2) + n1 + np.arange(n2) for i in range(per)])
    extra[np.ix_(rows_a, rows_a)] += sig_a
    extra[np.ix_(rows_b, rows_b)] += sig_b
    i = np.arange(n1)
    noise = linalg.block_diag(phi ** np.abs(i[:, None] - i[None, :]) / lam_a, np.eye(n2) / lam_b)
    ref = _raw(theta, x, kernels, a, k, y_star, theta_star, noise, w, extra)
    for algebra in (
        KronCalibrationDensity(theta, x, kernels, ktk, w, model.ls_weights()),
        dense,
    ):
        target = CalibrationPosterior(algebra, priors, (5.0, 5.0), observations=model)
        # a white output's out-of-basis remainder is in its lambda* prior (eq. 7)
        white = sum(
            model.remainder(q, model.gls(q, 0.0), [lam_a, lam_b][q])
            for q in range(2)
            if model.outputs[q].model == "white"
        )
        assert target(v) - target.log_prior(v) + white == pytest.approx(ref, rel=REL)
    # today's discrepancy on "a" gives another density (the test can fail)
    today = ObservationModel(
        (
            OutputNoise("a", (0, n1), (0, 1), "ar1" if phi else "white", discrepancy=True),
            model.outputs[1],
        ),
        k,
        y_star,
    )
    target = CalibrationPosterior(dense, priors, (5.0, 5.0), observations=today)
    assert target(v) - target.log_prior(v) != pytest.approx(ref, rel=1e-6)


def _perp(sigma: np.ndarray, f: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``sigma`` conditioned on ``f^T delta[rows] = 0``, written out."""
    sf = sigma[:, rows] @ f
    return sigma - sf @ np.linalg.solve(f.T @ sf[rows], sf.T)


@pytest.mark.parametrize(("error", "phi"), [("white", 0.0), ("ar1", 0.6)])
def test_the_kriged_discrepancy_is_the_dense_constrained_one_and_orthogonal(
    small_wall, error: str, phi: float
) -> None:
    # The simulator route: y* - y_sim = K delta + e, delta constrained at the draw's theta*.
    _, _, em = small_wall
    rng = np.random.default_rng(5)
    k = np.asarray(em.basis.k, dtype=float)
    (n, p), m = k.shape, em.x.shape[0]
    noise = OutputNoise("q", (0, n), tuple(range(p)), error, discrepancy="orthogonal")  # type: ignore[arg-type]
    obs = ObservationModel((noise,), k, rng.normal(size=(n, m)))
    x_new = np.vstack([em.x, rng.random((2, em.x.shape[1]))])  # every training period again
    y_sim = rng.normal(size=(n, m))
    theta = rng.random(em.theta.shape[1])
    lam_star, r = 12.0, 0.05
    values = {"lambda": em.lam, "lambda_star": lam_star, "phi": phi, "delta_rel": r}
    field = OutputDiscrepancy.build(em, obs, 0, x_new)
    with pytest.raises(ValueError, match="theta"):
        field.condition(values, obs.weights_of(0, y_sim, phi))
    shift, cov = field.condition(values, obs.weights_of(0, y_sim, phi), None, theta)

    # dense, in sample space, the constraint written on the training rows
    ktk = np.einsum("ij,ij->j", k, k)
    dense = DenseCalibrationDensity(em.theta, em.x, em.kernels, ktk, em.w, obs.ls_weights())
    grad = dense.mean_gradient(theta, 1.0 / (em.lam * ktk))  # (p, m, t)
    x_all = np.vstack([em.x, x_new])
    big, n_new = x_all.shape[0], x_new.shape[0]
    c_delta = linalg.block_diag(*[r * kern.variance * kern.x_corr(x_all) for kern in em.kernels])
    rows = (np.arange(p)[:, None] * big + np.arange(m)).ravel()
    c_delta = _perp(c_delta, (ktk[:, None, None] * grad).reshape(p * m, -1), rows)
    to_y = np.zeros((n * m, p * big))
    for j in range(p):
        to_y[:, j * big : j * big + m] = np.kron(np.eye(m), k[:, j][:, None])
    to_z = np.zeros((n_new * p, p * big))
    for a in range(n_new):
        for j in range(p):
            to_z[a * p + j, j * big + m + a] = 1.0
    i = np.arange(n)
    c_yy = to_y @ c_delta @ to_y.T + np.kron(np.eye(m), phi ** np.abs(i[:, None] - i) / lam_star)
    c_zy = to_z @ c_delta @ to_y.T
    resid = (obs.y_star - y_sim).T.reshape(-1)
    ref_mean = (c_zy @ np.linalg.solve(c_yy, resid)).reshape(n_new, p)
    ref_cov = to_z @ c_delta @ to_z.T - c_zy @ np.linalg.solve(c_yy, c_zy.T)
    np.testing.assert_allclose(shift, ref_mean, rtol=0, atol=REL * np.abs(ref_mean).max())
    for a in range(n_new):
        ref = ref_cov[a * p : (a + 1) * p, a * p : (a + 1) * p]
        np.testing.assert_allclose(cov[a], ref, rtol=0, atol=REL * np.abs(ref).max())
    # the kriged discrepancy at the training periods is orthogonal to the sensitivities
    at_train = shift[:m]  # (m, p)
    inner = np.einsum("j,ijk,ij->k", ktk, np.swapaxes(grad, 0, 1), at_train)
    scale = np.einsum("j,ijk,ij->k", ktk, np.abs(np.swapaxes(grad, 0, 1)), np.abs(at_train))
    assert np.all(np.abs(inner) < 1e-9 * scale)
    assert np.abs(at_train).max() > 1e-3  # and not zero


def test_loo_conditioning_with_a_block_diagonal_full_prior_is_the_per_basis_one() -> None:
    rng = np.random.default_rng(2)
    m, p = 5, 2
    x = rng.random((m, 1))
    prior = np.stack([0.3 * np.exp(-((x - x.T) ** 2) / 0.1), 0.1 * np.exp(-((x - x.T) ** 2))])
    blocks = np.tile(np.array([[0.05, 0.01], [0.01, 0.04]]), (m, 1, 1))
    diff = rng.normal(size=(m, p))
    full = np.zeros((p, m, p, m))
    for j in range(p):
        full[j, :, j, :] = prior[j]
    got, ref = loo_conditional(diff, full, blocks), loo_conditional(diff, prior, blocks)
    np.testing.assert_allclose(got[0], ref[0], rtol=1e-12)
    np.testing.assert_allclose(got[1], ref[1], rtol=1e-12)


def test_a_parameter_the_output_does_not_see_has_no_constraint() -> None:
    # rho = 1 switches theta_0 off in every basis: its sensitivity is exactly zero, and
    # the constraint keeps the other parameter's row only (a zero row would make
    # F^T Sigma F singular).
    rng = np.random.default_rng(6)
    t, runs, per, p = 2, 6, 5, 2
    kernels = []
    for _ in range(p):
        rho = rng.uniform(0.3, 0.9, t + 1)
        rho[0] = 1.0
        kernels.append(SeparableKernel(rho, 1.0, t))
    theta, x = rng.random((runs, t)), rng.random((per, 1))
    w = rng.normal(size=(runs * per, p))
    k = np.linalg.qr(rng.normal(size=(6, p)))[0]
    model = ObservationModel(
        (OutputNoise("q", (0, 6), (0, 1), "white", discrepancy="orthogonal"),), k,
        rng.normal(size=(6, per)),
    )  # fmt: skip
    ktk = np.einsum("ij,ij->j", k, k)
    fast = KronCalibrationDensity(theta, x, kernels, ktk, w, model.ls_weights())
    dense = DenseCalibrationDensity(theta, x, kernels, ktk, w, model.ls_weights())
    ts = rng.random(t)
    assert np.all(fast.mean_gradient(ts, np.full(p, 0.05))[:, :, 0] == 0.0)
    f = constraint_matrix(fast.mean_gradient(ts, np.full(p, 0.05)), ktk, [(0, 1)])
    assert f.shape == (p, per, 1)
    v = np.array([*ts, 20.0, 5.0, 0.3])
    values = []
    for algebra in (fast, dense):
        target = CalibrationPosterior(algebra, [UniformPrior(0.0, 1.0)] * t, (5.0, 5.0),
                                      observations=model)  # fmt: skip
        values.append(target(v))
    assert np.isfinite(values[0])
    assert values[0] == pytest.approx(values[1], rel=REL)


def test_the_emulator_route_equals_dense_conditioning_with_the_constraint(small_wall) -> None:
    # z = eta(theta*, x) + delta(x) at new periods given the runs' weights W and every
    # measured sample y* = K (eta + delta) + e, delta constrained on the training periods.
    _, _, em = small_wall
    rng = np.random.default_rng(11)
    k = np.asarray(em.basis.k, dtype=float)
    (n, p), m = k.shape, em.x.shape[0]
    noise = OutputNoise("q", (0, n), tuple(range(p)), "white", discrepancy="orthogonal")
    obs = ObservationModel((noise,), k, rng.normal(size=(n, m)))
    theta = rng.random(em.theta.shape[1])
    x_new = rng.random((2, em.x.shape[1]))
    x_all = np.vstack([em.x, x_new])
    big, n_new = x_all.shape[0], x_new.shape[0]
    lam_star, r = 40.0, 0.3
    values = {"lambda": em.lam, "lambda_star": lam_star, "delta_rel": r}
    field = OutputDiscrepancy.build(em, obs, 0, x_new)
    mean_w, _ = em.predict_weights(np.broadcast_to(theta, (big, theta.size)), x_all)
    eta_cov = em.weight_covariance(theta, x_all)
    shift, cov = field.condition(values, mean_w[:m], eta_cov, theta)
    got = mean_w[m:] + shift

    # dense: [W_0 .. W_p-1, y* (period-major), z (new, basis-minor)] over the latent
    # L = eta + delta (basis-major over the M periods)
    ktk = np.einsum("ij,ij->j", k, k)
    dense = DenseCalibrationDensity(em.theta, em.x, em.kernels, ktk, em.w, obs.ls_weights())
    grad = dense.mean_gradient(theta, 1.0 / (em.lam * ktk))
    z_sim = grid_inputs(em.theta, em.x)
    z_all = np.hstack([np.tile(theta, (big, 1)), x_all])
    n_sim = z_sim.shape[0]
    delta = linalg.block_diag(*[r * kern.variance * kern.x_corr(x_all) for kern in em.kernels])
    rows = (np.arange(p)[:, None] * big + np.arange(m)).ravel()
    latent = _perp(delta, (ktk[:, None, None] * grad).reshape(p * m, -1), rows)
    latent += linalg.block_diag(*[kern.full(z_all) for kern in em.kernels])
    cross = linalg.block_diag(*[kern.full(z_sim, z_all) for kern in em.kernels])
    sims = linalg.block_diag(
        *[kern.full(z_sim) + em.nuggets[j] * np.eye(n_sim) for j, kern in enumerate(em.kernels)]
    )
    to_y = np.zeros((n * m, p * big))
    for j in range(p):
        to_y[:, j * big : j * big + m] = np.kron(np.eye(m), k[:, j][:, None])
    to_z = np.zeros((n_new * p, p * big))
    for a in range(n_new):
        for j in range(p):
            to_z[a * p + j, j * big + m + a] = 1.0
    maps = np.vstack([to_y, to_z])
    full = np.block([[sims, cross @ maps.T], [maps @ cross.T, maps @ latent @ maps.T]])
    full[p * n_sim : p * n_sim + n * m, p * n_sim : p * n_sim + n * m] += np.eye(n * m) / lam_star
    obs_rows = np.arange(p * n_sim + n * m)
    tgt = np.arange(p * n_sim + n * m, full.shape[0])
    data = np.concatenate([em.w[:, j] for j in range(p)] + [obs.y_star.T.reshape(-1)])
    gain = np.linalg.solve(full[np.ix_(obs_rows, obs_rows)], full[np.ix_(obs_rows, tgt)]).T
    ref_mean = (gain @ data).reshape(n_new, p)
    ref_cov = full[np.ix_(tgt, tgt)] - gain @ full[np.ix_(obs_rows, tgt)]
    np.testing.assert_allclose(got, ref_mean, rtol=0, atol=REL * np.abs(ref_mean).max())
    for a in range(n_new):
        ref = ref_cov[a * p : (a + 1) * p, a * p : (a + 1) * p]
        np.testing.assert_allclose(cov[a], ref, rtol=0, atol=REL * np.abs(ref).max())
    assert np.abs(shift).max() > 1e-3  # conditioning moved something
