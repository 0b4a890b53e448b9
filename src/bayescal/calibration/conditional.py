"""The in-likelihood discrepancy conditioned on the training residuals (predictions).

An output declared with ``[outputs.errors.NAME] discrepancy = true`` is measured
as (method.md section 4a, standardised units, weights of the output's ``p_o``
basis vectors, one row per period)

    w_hat*_i = eta(theta*, x_i) + delta(x_i) + e_i,
    delta_j ~ GP(0, r tau_j^-1 c_x),   e_i ~ N(0, N),

with ``N`` the observed weights' noise block (white: ``(K_o^T K_o)^-1 /
lambda*``; AR(1): ``H0^-1 / lambda*``), the bases independent a priori and
periods independent in the noise. At one posterior draw (theta*, lambda*, phi,
r) everything is Gaussian, so the prediction of ``z = eta + delta`` at any
period, given the training periods' measured weights, is ordinary Gaussian
conditioning:

    mean(z_a) = m_a + G[a, O] Sigma^-1 (w_hat* - m_O),
    cov(z_a)  = G[a, a] - G[a, O] Sigma^-1 G[O, a],
    Sigma     = blockdiag_j G_j[O, O] + N (x) I,

where ``G_j = E_j + r tau_j^-1 C_x`` is the covariance of basis ``j`` of ``z``
over the training periods ``O`` and the predicted ones before the measurements
are seen, and ``m`` its mean. Two routes give ``m`` and ``E``:

* **simulator** (``[predict] method = "simulator"``): eta at theta*_s is the
  simulator re-run there, known exactly: ``m`` = the run's weights, ``E = 0``;
  only delta is kriged;
* **emulator**: ``m`` and ``E`` are the emulator's predictive mean and joint
  covariance at theta*_s over the periods (:meth:`Emulator.weight_covariance`),
  so eta and delta are conditioned on the measurements together, as in Kennedy
  and O'Hagan's predictive distribution (the emulator's own conditioning on
  the simulator runs is already in ``m`` and ``E``).

Each output is conditioned on its own measurements: given theta*, the bases of
different outputs are independent (block-diagonal basis, independent GPs,
independent noise). The conditioned discrepancy is what the training periods
taught about the model's error; on a test period whose conditions ``x`` lie
far from every training period it reverts to its prior (mean 0, variance ``r
tau^-1``), on one like a training period it carries that period's residual over.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize

from bayescal.calibration.orthogonal import Sensitivity, constrained_prior
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import ObservationModel

__all__ = ["OutputDiscrepancy", "krige_observed"]

FloatArray = NDArray[np.float64]


def krige_observed(
    resid: FloatArray, prior: FloatArray, noise: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Condition independent per-basis Gaussian fields on noisy observations of them.

    Parameters
    ----------
    resid
        Observed minus prior mean at the ``m`` observed periods ``(m, p)``. [-]
    prior
        Covariance of each basis's field before the observations, ``(p, M, M)``
        over ``M = m + P`` periods: the ``m`` observed ones first, then the
        ``P`` to predict; or ``(p, M, p, M)`` where the bases are correlated
        (the orthogonal discrepancy). [-]
    noise
        Covariance ``(p, p)`` of one observed period's errors (the same for
        every period, independent between periods). [-]

    Returns
    -------
    mean, cov
        The field at the ``P`` predicted periods given the observations: the
        shift of its mean ``(P, p)`` and its covariance within each period
        ``(P, p, p)``. [-]
    """
    m, p = resid.shape
    if prior.shape[0] != p or prior.shape[1] != prior.shape[-1] or prior.shape[1] < m:
        raise ValueError(f"prior {prior.shape} does not fit residuals {resid.shape}")
    if noise.shape != (p, p):
        raise ValueError(f"noise block {noise.shape} does not fit {p} bases")
    n_new = prior.shape[1] - m
    sigma = np.kron(noise, np.eye(m))  # rows basis-major: basis j, period i -> j m + i
    if prior.ndim == 4:  # bases correlated a priori
        sigma += prior[:, :m, :, :m].reshape(p * m, p * m)
        cross = prior[:, :m, :, m:].transpose(0, 1, 3, 2).reshape(p * m, n_new, p)
        own = np.einsum("kala->akl", prior[:, m:, :, m:])
    else:
        cross = np.zeros((p * m, n_new, p))
        for j in range(p):
            rows = slice(j * m, (j + 1) * m)
            sigma[rows, rows] += prior[j, :m, :m]
            cross[rows, :, j] = prior[j, :m, m:]
        own = np.zeros((n_new, p, p))
        own[:, np.arange(p), np.arange(p)] = np.stack(
            [np.diagonal(prior[j])[m:] for j in range(p)], axis=1
        )
    chol = linalg.cholesky(sigma, lower=True, check_finite=False)
    alpha = linalg.cho_solve((chol, True), resid.T.reshape(-1), check_finite=False)
    mean = np.einsum("ial,i->al", cross, alpha)
    half = linalg.solve_triangular(
        chol, cross.reshape(p * m, n_new * p), lower=True, check_finite=False
    ).reshape(p * m, n_new, p)
    cov = own - np.einsum("iak,ial->akl", half, half)
    return mean, cov


def same_periods(x: FloatArray) -> FloatArray:
    """``1`` where two rows of conditions ``(M, s)`` are the same period, else ``0``.

    A period predicted again (the training periods among the predicted ones)
    has exactly its own conditions; two different periods never have all of
    them equal (they are continuous summaries of the weather).
    """
    arr = np.atleast_2d(np.asarray(x, dtype=float))
    equal = np.all(arr[:, None, :] == arr[None, :, :], axis=2)
    return equal.astype(float)


@dataclass(frozen=True)
class OutputDiscrepancy:
    """The discrepancy of one output, ready to be conditioned draw by draw.

    Attributes
    ----------
    observations
        The error models and the measured training periods.
    q
        The output's index in ``observations``.
    x_corr
        ``c_x`` of each of its bases over the training periods, then the
        predicted ones, ``(p_o, M, M)``. [-]
    variances
        ``1 / tau_j`` of its bases ``(p_o,)``. [-]
    same_period
        ``1`` where two of these rows are the same period, else ``0``,
        ``(M, M)``: the correlation of the discrepancy's part independent
        between periods. [-]
    sensitivity
        ``F`` of an orthogonal discrepancy at any draw (the output's bases only),
        else ``None``: the part over the conditions is then conditioned on being
        orthogonal to the model's sensitivities at the draw's theta* over the
        training periods (:mod:`bayescal.calibration.orthogonal`).
    """

    observations: ObservationModel
    q: int
    x_corr: FloatArray
    variances: FloatArray
    same_period: FloatArray
    sensitivity: Sensitivity | None = None

    @classmethod
    def build(
        cls, emulator: Emulator, observations: ObservationModel, q: int, x_new: FloatArray
    ) -> OutputDiscrepancy:
        """Output ``q`` of ``observations`` (which must carry a discrepancy) at ``x_new``.

        Parameters
        ----------
        emulator
            The trained emulator (its correlation over ``x`` and ``1 / tau``).
        observations
            Error models and measured training periods (their ``x`` is the first
            ``m*`` rows of ``emulator.x``: an emulator extended to the test
            window, :meth:`~bayescal.emulator.gp.Emulator.extended`, has them first).
        q
            Output index.
        x_new
            Normalised conditions of the periods to predict ``(P, s)``. [-]
        """
        if q not in observations.delta_outputs:
            raise ValueError(f"output {observations.outputs[q].name!r} has no discrepancy")
        bases = list(observations.outputs[q].bases)
        x_obs = emulator.x[: observations.y_star.shape[1]]
        x_all = np.vstack([x_obs, np.atleast_2d(x_new)])
        kernels = emulator.kernels
        orthogonal = q in observations.orthogonal_outputs
        return cls(
            observations,
            q,
            np.stack([kernels[j].x_corr(x_all) for j in bases]),
            np.array([kernels[j].variance for j in bases]),
            same_periods(x_all),
            Sensitivity(emulator, x_obs.shape[0], [bases]) if orthogonal else None,
        )

    @property
    def n_train(self) -> int:
        """Training periods ``m*``."""
        return int(self.observations.y_star.shape[1])

    def condition(
        self,
        values: Mapping[str, float],
        model: FloatArray,
        eta_cov: FloatArray | None = None,
        theta: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """Shift and covariance of the predicted weights at one posterior draw.

        Parameters
        ----------
        values
            The draw's ``lambda*``, ``phi`` and ``r`` coordinates by name.
        model
            The model's weights at the draw's theta* on the training periods
            ``(m*, p_o)``: the simulator run's (estimated like the measured
            ones, :meth:`ObservationModel.weights_of`) or the emulator's mean. [-]
        eta_cov
            The emulator's joint covariance of the weights over the training and
            predicted periods ``(p_o, M, M)`` (emulator route); ``None`` when the
            model is the simulator itself. [-]
        theta
            The draw's theta* on the unit scale ``(t,)``: needed by an orthogonal
            discrepancy, whose constraint moves with it. [-]

        Returns
        -------
        shift, cov
            Added to the model's weights at the predicted periods ``(P, p_o)``,
            and the covariance of the (model + discrepancy) weights there
            ``(P, p_o, p_o)``. [-]
        """
        obs, q = self.observations, self.q
        lam = float(values[obs.coordinate("lambda_star", q)])
        phi = float(values[obs.coordinate("phi", q)]) if q in obs.ar_outputs else 0.0
        measured = obs.weights_of(q, obs.block(q)[1], phi)
        prior = self.prior(values, eta_cov, theta)
        return krige_observed(measured - model, prior, obs.noise_block(q, lam, phi))

    def prior(
        self,
        values: Mapping[str, float],
        eta_cov: FloatArray | None = None,
        theta: FloatArray | None = None,
    ) -> FloatArray:
        """The covariance of the (model +) discrepancy weights before the measurements,
        ``(p_o, M, M)``, or ``(p_o, M, p_o, M)`` for an orthogonal discrepancy
        (arguments as :meth:`condition`)."""
        obs, q = self.observations, self.q
        parts = obs.outputs[q].delta_parts
        prior = np.zeros_like(self.x_corr)
        if "delta_rel" in parts:
            r = float(values[obs.coordinate("delta_rel", q)])
            prior += (r * self.variances)[:, None, None] * self.x_corr
        if "delta_ind" in parts:
            r0 = float(values[obs.coordinate("delta_ind", q)])
            prior += (r0 * self.variances)[:, None, None] * self.same_period
        if eta_cov is not None:
            prior = prior + eta_cov
        if self.sensitivity is not None:  # "orthogonal": delta_rel alone, constrained
            if theta is None:
                raise ValueError("an orthogonal discrepancy is conditioned at the draw's theta*")
            f = self.sensitivity(theta, float(values["lambda"]))
            r = float(values[obs.coordinate("delta_rel", q)])
            full = constrained_prior((r * self.variances)[:, None, None] * self.x_corr, f)
            own = prior - (r * self.variances)[:, None, None] * self.x_corr  # eta's part
            p = own.shape[0]
            full[np.arange(p), :, np.arange(p), :] += own
            prior = full
        return prior

    def noise_given(
        self,
        values: Mapping[str, float],
        model: FloatArray,
        outside: tuple[float, float],
        theta: FloatArray | None = None,
    ) -> float:
        """The noise precision ``1 / E[1 / lambda*]`` given the simulator at one draw.

        With the model known (the simulator re-run at the draw's theta*, its
        weights ``model`` ``(m*, p_o)``) and the draw's ``phi`` and ``r``, the
        training residuals' weights ``e = w_hat* - model`` are
        ``N(0, A + B / lambda*)`` (``A`` the discrepancy's covariance over the
        training periods, ``B = (Z^T Z)^-1 (x) I`` the noise block at unit
        precision), and what the basis leaves of the residuals adds the Gamma
        ``outside`` ``(shape, rate)`` (the prior included,
        :meth:`ObservationModel.precision_out_of_basis`). The generalised
        eigenproblem ``A v = d B v`` makes the density of ``l = log lambda*``
        a sum over ``k``: ``shape l - rate e^l - 1/2 sum log(d_k + e^-l) -
        1/2 sum c_k^2 / (d_k + e^-l)``, ``c = V^T e``; ``E[1 / lambda*]`` is
        its quadrature on a grid of +-8 posterior SDs around the mode. This is
        the calibration's conditional of ``lambda*`` with the emulator's
        variance gone: the in-basis misfit that the discrepancy does not
        explain stays in the noise.
        """
        obs, q = self.observations, self.q
        m = self.n_train
        phi = float(values[obs.coordinate("phi", q)]) if q in obs.ar_outputs else 0.0
        resid = obs.weights_of(q, obs.block(q)[1], phi) - model  # (m, p)
        keep = np.all(np.isfinite(resid), axis=1)
        prior = self.prior(values, None, theta)
        p = resid.shape[1]
        if prior.ndim == 4:
            a = prior[:, :m, :, :m].reshape(p * m, p * m)
        else:
            a = linalg.block_diag(*[prior[j, :m, :m] for j in range(p)])
        b = np.kron(obs.noise_block(q, 1.0, phi), np.eye(m))
        rows = np.tile(keep, p)  # basis-major: basis j, period i -> j m + i
        a, b = a[np.ix_(rows, rows)], b[np.ix_(rows, rows)]
        d, v = linalg.eigh(0.5 * (a + a.T), 0.5 * (b + b.T), check_finite=False)
        d = np.clip(d, 0.0, None)
        c2 = (v.T @ resid[keep].T.reshape(-1)) ** 2
        shape, rate = outside

        def minus_log_post(ell: float) -> float:
            s2 = d + math.exp(-ell)
            return -(
                shape * ell
                - rate * math.exp(ell)
                - 0.5 * float(np.sum(np.log(s2)))
                - 0.5 * float(np.sum(c2 / s2))
            )

        centre = math.log(shape / rate)
        best = optimize.minimize_scalar(
            minus_log_post, bounds=(centre - 15.0, centre + 15.0), method="bounded"
        )
        mode = float(best.x)
        h = 1e-3
        curvature = (
            minus_log_post(mode + h) - 2.0 * minus_log_post(mode) + minus_log_post(mode - h)
        ) / (h * h)
        sd = 1.0 / math.sqrt(curvature) if curvature > 0 else 1.0
        grid = mode + np.linspace(-8.0, 8.0, 161) * sd
        log_w = -np.array([minus_log_post(float(g)) for g in grid])
        w = np.exp(log_w - log_w.max())
        mean_variance = float(np.sum(w * np.exp(-grid)) / np.sum(w))
        return 1.0 / mean_variance
