"""NUTS for the calibration posterior (eq. 16) in JAX (the extra ``bayescal[hmc]``).

The log posterior is that of
:class:`bayescal.calibration.posterior.CalibrationPosterior` on the full grid
of runs x periods with a uniform ``lambda*``, written in JAX through the
full-grid Schur route of :mod:`bayescal.calibration.kron`, on the fixed arrays
of :class:`~bayescal.calibration.grid.StackedGrid` (the observed periods placed
by ``obs_index``, as the numpy routes do) and the prior coefficients of
:class:`~bayescal.calibration.priors.CalibrationPriors`. A density evaluation
costs ``O(p (R^2 + R m*))`` like the numpy one.

NUTS runs on the unconstrained vector ``z = [logit u_1 .. logit u_t, log
lambda, log lambda*]`` with the log-Jacobian ``sum log u (1 - u) + log lambda
+ log lambda*`` added, by the generic engine :func:`bayescal.mcmc.nuts.run_nuts`;
:func:`sample_nuts_isolated`, which ``calibrate`` uses, runs it in a spawned
process (:func:`bayescal.mcmc.nuts.run_isolated`) so the caller never starts JAX.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import special

from bayescal.calibration.grid import StackedGrid
from bayescal.calibration.priors import CalibrationPriors
from bayescal.emulator.kernel import LOG_2PI, FloatArray
from bayescal.errors import ConfigError
from bayescal.mcmc.nuts import NutsChains, require_jax, run_isolated, run_nuts

if TYPE_CHECKING:
    from bayescal.calibration.target import CalibrationPosterior

__all__ = [
    "NutsResult",
    "jax_arrays",
    "jax_log_posterior",
    "log_jacobian",
    "sample_nuts",
    "sample_nuts_isolated",
    "to_constrained",
    "to_unconstrained",
]


def jax_arrays(grid: StackedGrid, priors: CalibrationPriors) -> dict[str, Any]:
    """The numpy arrays the JAX log posterior closes over (bases stacked).

    Parameters
    ----------
    grid
        The fixed arrays of eq. 16; every period must be observed.
    priors
        The priors of ``[u, lambda, lambda*]`` (uniform or Beta theta priors).

    Raises
    ------
    ConfigError
        If some period is not observed, or a prior is neither uniform nor Beta.
    """
    d = grid.data
    if not grid.full_grid or d.w_star is None:
        raise ConfigError(
            f"sampler 'nuts' needs every one of the {d.x.shape[0]} periods observed, "
            f"got {d.obs_index.size}",
            hint="use sampler 'mwg'",
        )
    a1, b1, const = priors.beta_coefficients()
    return {
        "theta": np.asarray(grid.theta, dtype=float),
        "beta_theta": np.ascontiguousarray(grid.beta_theta.T),  # (p, t)
        "variance": grid.variance,
        "q_t_trans": grid.q_t_trans,
        "l_t": grid.l_t,
        "l_x": grid.l_x,
        "w_rot": grid.w_rot,
        "obs_rot": grid.obs_rot,
        "ktk": np.asarray(grid.ktk, dtype=float),
        "prior_a1": a1,
        "prior_b1": b1,
        "prior_const": const,
        "size": float(grid.size),
        "lam_prior": priors.lam,
        "lam_star_prior": priors.lam_star,
        "t": priors.t,
    }


def _likelihood(jnp: Any, c: dict[str, Any], u: Any, lam: Any, lam_star: Any) -> Any:
    """``sum_j log N(v_j; 0, Omega_j)`` by the full-grid Schur route (kron.py)."""
    a = 1.0 / (lam * c["ktk"])
    a_star = 1.0 / (lam_star * c["ktk"])
    den = c["l_t"][:, :, None] * c["l_x"][:, None, :] + a[:, None, None]
    diff = c["theta"] - u
    cov = jnp.exp(-((diff * diff) @ c["beta_theta"].T)) * c["variance"]  # (R, p)
    c_hat = jnp.einsum("pkr,rp->pk", c["q_t_trans"], cov)
    den_ok = jnp.all(den > 0.0)
    den = jnp.where(den > 0.0, den, 1.0)  # keeps gradients finite where rejected
    h = c["w_rot"] / den
    l_x = c["l_x"]
    u_vec = l_x * jnp.einsum("pk,pki->pi", c_hat, h)
    g = l_x * l_x * jnp.einsum("pk,pki->pi", c_hat * c_hat, 1.0 / den)
    schur = c["variance"][:, None] * l_x + a_star[:, None] - g
    schur_ok = jnp.all(schur > 0.0)
    schur = jnp.where(schur > 0.0, schur, 1.0)
    resid = c["obs_rot"] - u_vec
    logdet = jnp.sum(jnp.log(den)) + jnp.sum(jnp.log(schur))
    quad = jnp.sum(c["w_rot"] * h) + jnp.sum(resid * resid / schur)
    value = -0.5 * (c["size"] * LOG_2PI + logdet + quad)
    return jnp.where(den_ok & schur_ok, value, -jnp.inf)


def _gamma_terms(c: dict[str, Any], log_lam: Any, lam: Any, log_ls: Any, lam_s: Any) -> Any:
    shape, rate = c["lam_prior"]
    shape_s, rate_s = c["lam_star_prior"]
    return (shape - 1.0) * log_lam - rate * lam + (shape_s - 1.0) * log_ls - rate_s * lam_s


def jax_log_posterior(
    arrays: dict[str, Any],
) -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
    """The log posterior in JAX, on the constrained and the unconstrained scale.

    Parameters
    ----------
    arrays
        From :func:`jax_arrays`.

    Returns
    -------
    constrained
        ``v = [u, lambda, lambda*] -> log p`` equal to ``CalibrationPosterior(v)``
        (``-inf`` outside the support).
    unconstrained
        ``z = [logit u, log lambda, log lambda*] -> log p + log |dv/dz|``.
    """
    jax, _ = require_jax()
    jnp = jax.numpy
    c: dict[str, Any] = {
        name: jnp.asarray(arrays[name])
        for name in (
            "theta",
            "beta_theta",
            "variance",
            "q_t_trans",
            "l_t",
            "l_x",
            "w_rot",
            "obs_rot",
            "ktk",
            "prior_a1",
            "prior_b1",
            "prior_const",
        )
    }
    c |= {"size": arrays["size"], "lam_prior": arrays["lam_prior"]}
    c["lam_star_prior"] = arrays["lam_star_prior"]
    t = int(arrays["t"])

    def theta_prior(log_u: Any, log_1mu: Any) -> Any:
        return jnp.sum(c["prior_a1"] * log_u + c["prior_b1"] * log_1mu + c["prior_const"])

    def constrained(v: Any) -> Any:
        u, lam, lam_s = v[:t], v[t], v[t + 1]
        inside = jnp.all((u >= 0.0) & (u <= 1.0)) & (lam > 0.0) & (lam_s > 0.0)
        u_in = jnp.clip(u, 0.0, 1.0)
        lam_in, lam_s_in = jnp.where(lam > 0.0, lam, 1.0), jnp.where(lam_s > 0.0, lam_s, 1.0)
        a1, b1 = c["prior_a1"], c["prior_b1"]
        prior = jnp.sum(
            jax.scipy.special.xlogy(a1, u_in)
            + jax.scipy.special.xlog1py(b1, -u_in)
            + c["prior_const"]
        )
        prior += _gamma_terms(c, jnp.log(lam_in), lam_in, jnp.log(lam_s_in), lam_s_in)
        value = prior + _likelihood(jnp, c, u_in, lam_in, lam_s_in)
        return jnp.where(inside, value, -jnp.inf)

    def unconstrained(z: Any) -> Any:
        zu, log_lam, log_ls = z[:t], z[t], z[t + 1]
        log_u, log_1mu = -jax.nn.softplus(-zu), -jax.nn.softplus(zu)
        lam, lam_s = jnp.exp(log_lam), jnp.exp(log_ls)
        prior = theta_prior(log_u, log_1mu) + _gamma_terms(c, log_lam, lam, log_ls, lam_s)
        jacobian = jnp.sum(log_u + log_1mu) + log_lam + log_ls
        return prior + jacobian + _likelihood(jnp, c, jax.nn.sigmoid(zu), lam, lam_s)

    return constrained, unconstrained


def to_unconstrained(v: Any, t: int) -> FloatArray:
    """``[u, lambda, lambda*]`` (``(..., t + 2)``) to ``[logit u, log lambda, log lambda*]``."""
    arr = np.asarray(v, dtype=float)
    return np.concatenate([special.logit(arr[..., :t]), np.log(arr[..., t:])], axis=-1)


def to_constrained(z: Any, t: int) -> FloatArray:
    """Inverse of :func:`to_unconstrained`."""
    arr = np.asarray(z, dtype=float)
    return np.concatenate([special.expit(arr[..., :t]), np.exp(arr[..., t:])], axis=-1)


def log_jacobian(z: Any, t: int) -> FloatArray:
    """``log |dv/dz|`` of :func:`to_constrained`, summed over the last axis."""
    arr = np.asarray(z, dtype=float)
    zu = arr[..., :t]
    logistic = -(np.logaddexp(0.0, -zu) + np.logaddexp(0.0, zu))
    out: FloatArray = logistic.sum(axis=-1) + arr[..., t:].sum(axis=-1)
    return out


@dataclass(frozen=True)
class NutsResult:
    """NUTS draws of the calibration posterior, mapped back to ``[u, lambda, lambda*]``.

    Attributes
    ----------
    draws
        ``[u, lambda, lambda*]`` after warm-up, ``(chains, draws, t + 2)``. [-]
    log_density
        Log posterior (as ``CalibrationPosterior``, Jacobian removed) at the
        draws, ``(chains, draws)``.
    chains
        The chains on the unconstrained scale, with their sampler statistics.
    """

    draws: FloatArray
    log_density: FloatArray
    chains: NutsChains


def sample_nuts(
    target: CalibrationPosterior,
    starts: Any,
    n_burn: int,
    n_draws: int,
    seed: int,
    *,
    vectorised: bool = False,
    callback: Callable[[int], None] | None = None,
    max_num_doublings: int = 10,
) -> NutsResult:
    """NUTS on the calibration posterior ``target`` (see the module docstring).

    Parameters
    ----------
    target
        The numpy log posterior (its algebra's stacked grid and its priors).
    starts
        Starting points ``[u, lambda, lambda*]``, ``(chains, t + 2)``, inside the support.
    n_burn, n_draws, seed, vectorised, callback, max_num_doublings
        As :func:`run_nuts`.
    """
    arrays = jax_arrays(target.grid(), target.prior_terms)
    t = int(arrays["t"])
    _, logdensity = jax_log_posterior(arrays)
    chains = run_nuts(
        logdensity,
        to_unconstrained(starts, t),
        n_burn,
        n_draws,
        seed,
        vectorised=vectorised,
        callback=callback,
        max_num_doublings=max_num_doublings,
    )
    z = chains.position
    return NutsResult(to_constrained(z, t), chains.logdensity - log_jacobian(z, t), chains)


def sample_nuts_isolated(
    target: CalibrationPosterior,
    starts: Any,
    n_burn: int,
    n_draws: int,
    seed: int,
    *,
    callback: Callable[[int], None] | None = None,
    **kwargs: Any,
) -> NutsResult:
    """:func:`sample_nuts` in a fresh ``spawn``-ed process; same draws.

    See :func:`bayescal.mcmc.nuts.run_isolated` (the caller never starts JAX).

    Parameters
    ----------
    target, starts, n_burn, n_draws, seed, callback
        As :func:`sample_nuts`; ``callback`` is called in this process.
    **kwargs
        Further keyword arguments of :func:`sample_nuts`.
    """
    result: NutsResult = run_isolated(
        sample_nuts, target, starts, n_burn, n_draws, seed, callback=callback, **kwargs
    )
    return result
