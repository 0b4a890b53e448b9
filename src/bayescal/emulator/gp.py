"""The trained Gaussian-process emulator: prediction and leave-one-run-out CV.

Prediction
----------
With hyperparameters fixed at the MAP, each basis weight at a new input
``z0 = [theta0, x0]`` is predicted by the GP conditional on the training
weights (exact, through the Kronecker eigen-decomposition), then mapped
through ``K`` and the standardisation. The variance of an output sample is
``sum_j k_j^2 var(w_j) + 1 / lambda`` (latent-weight uncertainty plus the
simulator's out-of-basis part, eq. 3) times ``sd^2``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike
from scipy import special

from bayescal.emulator.assemble import OutputStack
from bayescal.emulator.basis import Basis, InputPCA, Normaliser
from bayescal.emulator.hyper import HyperLayout, HyperPriors
from bayescal.emulator.kernel import FloatArray, SeparableKernel
from bayescal.emulator.kron import SymEig
from bayescal.errors import DataError

__all__ = ["ConditionalPieces", "Emulator", "LooResult"]


@dataclass(frozen=True)
class _Conditional:
    """GP of one basis conditioned on weights on a grid (hyperparameters fixed)."""

    kernel: SeparableKernel
    theta: FloatArray  # (R, t)
    x: FloatArray  # (m*, s)
    q_t: FloatArray  # eigenvectors of S_theta (with tau^-1)
    q_x: FloatArray  # eigenvectors of S_x
    inv_den: FloatArray  # 1 / (l_k l_i + a), (R, m*)
    h: FloatArray  # A^-1 w as an (R, m*) matrix

    @classmethod
    def build(
        cls, kernel: SeparableKernel, theta: FloatArray, x: FloatArray, v: FloatArray, a: float
    ) -> _Conditional:
        eig_t = SymEig.of(kernel.theta_cov(theta))
        eig_x = SymEig.of(kernel.x_corr(x))
        den = np.multiply.outer(eig_t.values, eig_x.values) + a
        rot = eig_t.vectors.T @ v @ eig_x.vectors
        h = eig_t.vectors @ (rot / den) @ eig_x.vectors.T
        return cls(kernel, theta, x, eig_t.vectors, eig_x.vectors, 1.0 / den, h)

    def predict(self, theta_new: FloatArray, x_new: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Mean and variance ``(q,)`` of the latent weight at ``q`` paired inputs."""
        c_t = self.kernel.theta_cov(theta_new, self.theta)  # (q, R), carries tau^-1
        c_x = self.kernel.x_corr(x_new, self.x)  # (q, m*)
        mean = np.sum((c_t @ self.h) * c_x, axis=1)
        a_t = c_t @ self.q_t
        a_x = c_x @ self.q_x
        reduction = np.sum(((a_t * a_t) @ self.inv_den) * (a_x * a_x), axis=1)
        return mean, np.maximum(self.kernel.variance - reduction, 0.0)

    def joint_cov(self, theta_new: FloatArray, x_new: FloatArray) -> FloatArray:
        """Covariance ``(P, P)`` of the latent weight at one theta and ``P`` periods.

        ``c(z_a, z_b) - c_a^T A^-1 c_b`` with ``z = [theta, x]``: in the
        eigenbases the reduction is ``a_x diag(sum_k a_t,k^2 / (l_k l_i + a)) a_x^T``.
        """
        c_t = self.kernel.theta_cov(theta_new[None, :], self.theta)  # (1, R)
        a_t = (c_t @ self.q_t)[0]
        weight = (a_t * a_t) @ self.inv_den  # (m*,)
        a_x = self.kernel.x_corr(x_new, self.x) @ self.q_x  # (P, m*)
        prior = float(self.kernel.theta_cov(theta_new[None, :])[0, 0]) * self.kernel.x_corr(x_new)
        out: FloatArray = prior - (a_x * weight) @ a_x.T
        return out

    def leave_one_run_out(self, v: FloatArray, a: float) -> tuple[FloatArray, FloatArray]:
        """Latent mean and variance ``(R, m*)`` of each run predicted from the others.

        Closed form of dropping run ``b`` (all its periods) and conditioning on
        the rest: with ``A = S_theta ⊗ S_x + a I`` and ``P = A^-1``, the
        predictive covariance of ``v_b`` is ``(P_bb)^-1`` and its mean
        ``v_b - (P_bb)^-1 (A^-1 v)_b``. Since ``P_bb = Q_x diag(g_b) Q_x^T`` with
        ``g_b,i = sum_k Q_theta[b, k]^2 / (l_k l_i + a)``, every run costs
        ``O(m*^2)`` instead of a new ``O(R^3 + m*^3)`` factorisation.

        Parameters
        ----------
        v
            The training weights of this basis on the grid ``(R, m*)``. [-]
        a
            The nugget the covariance was built with. [-]
        """
        g = (self.q_t * self.q_t) @ self.inv_den  # (R, m*)
        mean = v - ((self.h @ self.q_x) / g) @ self.q_x.T
        var = (1.0 / g) @ (self.q_x * self.q_x).T - a
        return mean, np.maximum(var, 0.0)


@dataclass(frozen=True)
class ConditionalPieces:
    """The factorised training covariance of every basis, stacked over bases.

    Stored in the artefact so that a loaded emulator predicts bit for bit what the
    saved one did (a fresh eigen-decomposition may differ in the last bits).

    Attributes
    ----------
    q_t
        Eigenvectors of ``S_theta``, ``(p, R, R)``.
    q_x
        Eigenvectors of ``S_x``, ``(p, m*, m*)``.
    inv_den
        ``1 / (l_k l_i + a)``, ``(p, R, m*)``.
    h
        ``A^-1 w`` as ``(p, R, m*)``.
    """

    q_t: FloatArray
    q_x: FloatArray
    inv_den: FloatArray
    h: FloatArray


@dataclass(frozen=True)
class LooResult:
    """Leave-one-run-out cross-validation of the emulator.

    Attributes
    ----------
    rmse
        Output name -> RMSE over all held-out runs, periods and samples, in the
        output's unit.
    output_sd
        Output name -> SD of the simulated output over all runs, periods and
        samples, same unit (the scale the RMSE is judged against).
    rmse_run
        RMSE per held-out run and output, ``(R, n_outputs)``.
    z
        Standardised residuals ``(y - mean) / sd_pred``, ``(R, N, m*)``. [-]
    """

    rmse: dict[str, float]
    output_sd: dict[str, float]
    rmse_run: FloatArray
    z: FloatArray

    def coverage(self, level: float = 0.95) -> float:
        """Fraction of held-out samples inside their central ``level`` band."""
        half = float(special.ndtri(0.5 + 0.5 * level))
        return float(np.mean(np.abs(self.z) <= half))


@dataclass(frozen=True)
class Emulator:
    """A trained emulator (immutable): data, hyperparameters at the MAP and their draws.

    Attributes
    ----------
    parameter_names
        Calibration parameters (the first ``t`` inputs).
    input_labels
        Labels of all ``r`` inputs ``[theta, x]``.
    theta_normaliser
        Prior bounds of theta (physical <-> [0, 1]).
    outputs
        Standardisation and stacking of the outputs.
    basis
        Output PCA basis ``K``.
    inputs
        PCA of the boundary conditions (``inputs.transform`` gives ``x`` of new periods).
    theta
        Normalised design ``(R, t)``. [-]
    x
        Normalised variable conditions of the training periods ``(m*, s)``. [-]
    w
        Training weights ``(R m*, p)``, run-major. [-]
    y_std
        Standardised training simulations ``(N, R m*)`` (for cross-validation). [-]
    beta
        MAP ``-4 ln rho``, ``(p, r)``. [-]
    tau
        MAP GP precisions ``(p,)``. [-]
    lam
        MAP simulator precision ``lambda``. [-]
    lam_prior
        ``(shape, rate)`` of the Gamma prior of ``lambda`` (eq. 7).
    hyper_draws
        Posterior draws of the hyperparameter vector ``(chains, draws, d)``.
    hyper_lp
        Log posterior at the draws ``(chains, draws)``.
    hyper_acceptance
        Acceptance rate per chain and coordinate ``(chains, d)``.
    best_draw
        The draw with the highest log-scale posterior density ``(d,)``.
    log_post_best, log_post_map
        Log-scale posterior density (up to a constant) at the best draw and at the MAP.
    seed
        Root seed of the training chains.
    hyper_priors
        Priors of ``tau`` and ``rho``.
    conditional
        The factorised training covariances; computed from the above when
        omitted (given when an emulator is read back from its artefact).
    """

    parameter_names: tuple[str, ...]
    input_labels: tuple[str, ...]
    theta_normaliser: Normaliser
    outputs: OutputStack
    basis: Basis
    inputs: InputPCA
    theta: FloatArray
    x: FloatArray
    w: FloatArray
    y_std: FloatArray
    beta: FloatArray
    tau: FloatArray
    lam: float
    lam_prior: tuple[float, float]
    hyper_draws: FloatArray
    hyper_lp: FloatArray
    hyper_acceptance: FloatArray
    best_draw: FloatArray
    log_post_best: float
    log_post_map: float
    seed: int
    hyper_priors: HyperPriors = field(default_factory=HyperPriors)
    conditional: ConditionalPieces | None = field(default=None, repr=False, compare=False)
    _cond: tuple[_Conditional, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        pc = self.conditional
        if pc is None:
            n_runs, n_per = self.theta.shape[0], self.x.shape[0]
            grid = self.w.T.reshape(self.basis.p, n_runs, n_per)
            nug = self.nuggets
            cond = [
                _Conditional.build(k, self.theta, self.x, grid[j], float(nug[j]))
                for j, k in enumerate(self.kernels)
            ]
            pc = ConditionalPieces(
                np.stack([c.q_t for c in cond]),
                np.stack([c.q_x for c in cond]),
                np.stack([c.inv_den for c in cond]),
                np.stack([c.h for c in cond]),
            )
            object.__setattr__(self, "conditional", pc)
        cond_t = tuple(
            _Conditional(k, self.theta, self.x, pc.q_t[j], pc.q_x[j], pc.inv_den[j], pc.h[j])
            for j, k in enumerate(self.kernels)
        )
        object.__setattr__(self, "_cond", cond_t)

    @property
    def pieces(self) -> ConditionalPieces:
        """The factorised training covariances (always set after construction)."""
        if self.conditional is None:  # pragma: no cover - __post_init__ sets it
            raise RuntimeError("emulator was built without its conditional pieces")
        return self.conditional

    @property
    def layout(self) -> HyperLayout:
        """Positions of the hyperparameters in ``hyper_draws``."""
        return HyperLayout(self.basis.p, len(self.input_labels))

    @property
    def hyper_names(self) -> list[str]:
        """Names of the hyperparameter coordinates."""
        return self.layout.names(self.input_labels)

    @property
    def kernels(self) -> tuple[SeparableKernel, ...]:
        """One :class:`SeparableKernel` per basis at the MAP."""
        t = len(self.parameter_names)
        return tuple(
            SeparableKernel.from_beta(self.beta[j], float(self.tau[j]), t)
            for j in range(self.basis.p)
        )

    @property
    def rho(self) -> FloatArray:
        """MAP correlation parameters ``(p, r)``: sensitivity (small = influential)."""
        return np.exp(-0.25 * self.beta)

    @property
    def nuggets(self) -> FloatArray:
        """``(lambda k_j^T k_j)^-1`` per basis ``(p,)``."""
        return 1.0 / (self.lam * self.basis.ktk)

    def _pairs(self, theta_unit: ArrayLike, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        t, s = len(self.parameter_names), self.x.shape[1]
        th = np.atleast_2d(np.asarray(theta_unit, dtype=float))
        xx = np.atleast_2d(np.asarray(x, dtype=float))
        if th.shape[1] != t or xx.shape[1] != s:
            raise DataError(
                f"expected theta with {t} columns and x with {s} columns, "
                f"got shapes {th.shape} and {xx.shape}"
            )
        q = max(th.shape[0], xx.shape[0])
        if th.shape[0] not in (1, q) or xx.shape[0] not in (1, q):
            raise DataError(f"theta has {th.shape[0]} rows and x {xx.shape[0]}; expected equal")
        return np.broadcast_to(th, (q, t)), np.broadcast_to(xx, (q, s))

    def extended(self, x_new: ArrayLike, y_new_std: ArrayLike) -> Emulator:
        """The same emulator (hyperparameters kept) conditioned on more periods of the runs.

        Parameters
        ----------
        x_new
            Normalised conditions of ``P`` further periods, ``(P, s)``. [-]
        y_new_std
            The design runs on those periods, standardised like ``y_std``,
            ``(N, R P)``, run-major columns. [-]

        Returns
        -------
        Emulator
            Its grid is the ``R`` runs x the ``m* + P`` periods (training periods
            first): it predicts at the new periods by interpolating in ``theta``
            between runs made under those very conditions, not by extrapolating in
            ``x``. Its leave-one-run-out CV covers all ``m* + P`` periods.
        """
        xx = np.atleast_2d(np.asarray(x_new, dtype=float))
        y_new = np.asarray(y_new_std, dtype=float)
        n_runs, n_per, n_new = self.theta.shape[0], self.x.shape[0], xx.shape[0]
        if xx.shape[1] != self.x.shape[1] or y_new.shape != (self.y_std.shape[0], n_runs * n_new):
            raise DataError(
                f"expected x of {n_new} periods with {self.x.shape[1]} columns and runs "
                f"{(self.y_std.shape[0], n_runs * n_new)}, got {xx.shape} and {y_new.shape}"
            )
        n = self.y_std.shape[0]
        y_all = np.concatenate(
            [self.y_std.reshape(n, n_runs, n_per), y_new.reshape(n, n_runs, n_new)], axis=2
        ).reshape(n, -1)
        return replace(
            self,
            x=np.vstack([self.x, xx]),
            y_std=y_all,
            w=self.basis.weights(y_all),
            conditional=None,
        )

    def predict_weights(self, theta_unit: ArrayLike, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Predictive mean and variance of the weights ``(q, p)`` at normalised inputs.

        Parameters
        ----------
        theta_unit
            Normalised parameters ``(q, t)`` or ``(t,)``. [-]
        x
            Normalised variable conditions ``(q, s)`` or ``(s,)``. [-]
        """
        th, xx = self._pairs(theta_unit, x)
        parts = [c.predict(th, xx) for c in self._cond]
        return np.column_stack([m for m, _ in parts]), np.column_stack([v for _, v in parts])

    def weight_covariance(
        self, theta_unit: ArrayLike, x: ArrayLike, bases: Sequence[int] | None = None
    ) -> FloatArray:
        """Joint predictive covariance of the weights over periods at one theta, ``(p, P, P)``.

        Each basis's weights at the normalised parameters ``theta_unit`` ``(t,)`` and
        the ``P`` periods ``x`` ``(P, s)``, conditional on the training runs
        (hyperparameters at the MAP); the diagonal is :meth:`predict_weights`'s
        variance. Bases are independent; ``bases`` picks some of them (all if
        ``None``), in that order.
        """
        th = np.asarray(theta_unit, dtype=float).reshape(-1)
        xx = np.atleast_2d(np.asarray(x, dtype=float))
        if th.size != len(self.parameter_names) or xx.shape[1] != self.x.shape[1]:
            raise DataError(
                f"expected theta of {len(self.parameter_names)} values and x with "
                f"{self.x.shape[1]} columns, got {th.size} and {xx.shape[1]}"
            )
        picked = range(len(self._cond)) if bases is None else bases
        return np.stack([self._cond[j].joint_cov(th, xx) for j in picked])

    def predict_std(
        self, theta_unit: ArrayLike, x: ArrayLike, *, out_of_basis: bool = True
    ) -> tuple[FloatArray, FloatArray]:
        """Mean and variance of standardised output ``(N, q)`` at normalised inputs.

        ``out_of_basis=False`` leaves the out-of-basis variance ``1 / lambda`` out
        of the variance (the calibrated bands carry it in the noise, method.md
        section 6).
        """
        mean_w, var_w = self.predict_weights(theta_unit, x)
        k = self.basis.k
        var = (k * k) @ var_w.T
        return k @ mean_w.T, var + 1.0 / self.lam if out_of_basis else var

    def predict(
        self, theta_phys: ArrayLike, x: ArrayLike, *, out_of_basis: bool = True
    ) -> tuple[FloatArray, FloatArray]:
        """Predictive mean and variance of the simulator output in physical units.

        Parameters
        ----------
        theta_phys
            Parameters in physical units, ``(q, t)`` or ``(t,)`` (broadcast
            against ``x``).
        x
            Normalised variable conditions of the periods, ``(q, s)`` or ``(s,)``
            (rows of ``Assembled.x`` or ``inputs.transform(...)``). [-]
        out_of_basis
            Include the out-of-basis noise ``1 / lambda`` in the variance.

        Returns
        -------
        mean, variance
            ``(N, q)`` each: column ``i`` is the period at input pair ``i``,
            outputs stacked along the rows (``outputs.split``), mean in the
            outputs' units, variance in their squares. The variance includes
            the out-of-basis noise ``1 / lambda`` unless ``out_of_basis`` is False.
        """
        th, xx = self._pairs(theta_phys, x)
        mean, var = self.predict_std(self.theta_normaliser.apply(th), xx, out_of_basis=out_of_basis)
        sd = self.outputs.sd[:, None]
        return self.outputs.invert(mean), var * sd * sd

    def loo_predict(self) -> tuple[FloatArray, FloatArray]:
        """Leave-one-run-out predictions, standardised, hyperparameters at the MAP.

        Each run is predicted from the other ``R - 1`` in closed form
        (:meth:`_Conditional.leave_one_run_out`); equal to refitting without the
        run to rounding (``tests/emulator/test_gp.py``).

        Returns
        -------
        mean, variance
            ``(R, N, m*)`` each on the standardised scale; the variance includes
            the out-of-basis noise ``1 / lambda``.
        """
        n_runs, n_per = self.theta.shape[0], self.x.shape[0]
        grid = self.w.T.reshape(self.basis.p, n_runs, n_per)
        parts = [
            cond.leave_one_run_out(grid[j], float(a))
            for j, (cond, a) in enumerate(zip(self._cond, self.nuggets, strict=True))
        ]
        mean_w = np.stack([m for m, _ in parts])  # (p, R, m*)
        var_w = np.stack([v for _, v in parts])
        k = self.basis.k
        mean = np.einsum("np,prm->rnm", k, mean_w)
        var = np.einsum("np,prm->rnm", k * k, var_w) + 1.0 / self.lam
        return mean, var

    def loo_cv(self) -> LooResult:
        """Leave-one-run-out cross-validation (hyperparameters fixed at the MAP)."""
        n_runs, n_per = self.theta.shape[0], self.x.shape[0]
        sd = self.outputs.sd[:, None]
        mean, var = self.loo_predict()
        sim = self.y_std.reshape(-1, n_runs, n_per).transpose(1, 0, 2)
        resid = sim - mean
        z = resid / np.sqrt(var)
        sq = np.mean((resid * sd) ** 2, axis=2)
        slices = self.outputs.slices
        phys = self.outputs.invert(self.y_std)
        return LooResult(
            rmse={n: float(np.sqrt(np.mean(sq[:, sl]))) for n, sl in slices.items()},
            output_sd={n: float(np.std(phys[sl])) for n, sl in slices.items()},
            rmse_run=np.column_stack(
                [np.sqrt(np.mean(sq[:, sl], axis=1)) for sl in slices.values()]
            ),
            z=z,
        )
