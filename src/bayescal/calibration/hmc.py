"""No-U-Turn sampling of the calibration posterior (eq. 16) with JAX and BlackJAX.

An optional extra (``pip install "bayescal[hmc]"``): JAX and BlackJAX are
imported only when a function here needs them; without them
:func:`require_jax` raises :class:`bayescal.errors.ConfigError` with the
install command.

The log posterior is that of
:class:`bayescal.calibration.posterior.CalibrationPosterior` on the full grid
of runs x periods with a uniform ``lambda*`` (what
:func:`bayescal.calibration.posterior.calibrate` samples),
written in JAX through the Schur route of :mod:`bayescal.emulator.kron`.
Everything that does not move with ``theta*``, ``lambda`` or ``lambda*`` is
computed once in numpy (:func:`fixed_arrays`): per basis ``j`` the
eigen-decompositions ``S_theta = Q_t L_t Q_t^T`` and ``S_x = Q_x L_x Q_x^T``,
the rotated weights ``Wt = Q_t^T W Q_x`` and observations ``Q_x^T w*``. A
density evaluation then costs ``O(p (R^2 + R m*))`` like the numpy one.

NUTS runs on the unconstrained vector ``z = [logit u_1 .. logit u_t, log
lambda, log lambda*]`` with the log-Jacobian ``sum log u (1 - u) + log lambda
+ log lambda*`` added, and Stan-style window adaptation of the step size and a
diagonal inverse mass matrix (BlackJAX's ``window_adaptation``). JAX runs in
float64 (``jax_enable_x64`` is switched on for the whole process when JAX is
first used here). The chains run one after another: on 2 CPU cores,
vmapping the 4 chains into one program sampled about 2x faster but took about
twice as long to compile (~13 instead of ~6.5 CPU s), a loss at 500 + 1000
iterations (benchmarks/bench_hmc.py ``--variants``).

Once JAX has started its runtime in a process, any later ``os.fork()`` there
(the process pools of the runner and of the MwG chains) may deadlock, and JAX
warns about it. :func:`sample_nuts_isolated`, which ``calibrate`` uses, runs
NUTS in a fresh ``spawn``-ed process so that the caller never starts JAX; as
with any ``spawn``, a script that calls it must guard its top level with
``if __name__ == "__main__":``.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from queue import Empty
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy import special

from bayescal.design import BetaPrior, Prior, UniformPrior
from bayescal.emulator.dense import GridData
from bayescal.emulator.kernel import LOG_2PI, FloatArray
from bayescal.emulator.kron import SymEig
from bayescal.errors import ConfigError
from bayescal.optional import module_installed

if TYPE_CHECKING:
    from bayescal.calibration.posterior import CalibrationPosterior

__all__ = [
    "FixedArrays",
    "NutsChains",
    "NutsResult",
    "fixed_arrays",
    "jax_log_posterior",
    "require_jax",
    "run_nuts",
    "sample_nuts",
    "sample_nuts_isolated",
]

INSTALL_HINT = 'install the extra: pip install "bayescal[hmc]"'


def _missing(name: str | None) -> ConfigError:
    return ConfigError(
        f"sampler 'nuts' needs JAX and BlackJAX, which are not installed ({name} missing)",
        hint=INSTALL_HINT,
    )


def check_installed() -> None:
    """Raise the one-line ConfigError of :func:`require_jax` without importing anything."""
    for name in ("jax", "blackjax"):
        if not module_installed(name):
            raise _missing(name)


def require_jax() -> tuple[ModuleType, ModuleType]:
    """Import JAX (float64 switched on) and BlackJAX, or raise a one-line ConfigError."""
    try:
        import blackjax
        import jax
    except ImportError as exc:
        raise _missing(exc.name) from exc
    jax.config.update("jax_enable_x64", True)
    return jax, blackjax


@dataclass(frozen=True)
class FixedArrays:
    """What the calibration log posterior needs that never moves (numpy, bases stacked).

    Attributes
    ----------
    theta
        Design ``(R, t)``, scaled to [0, 1]. [-]
    beta_theta
        ``-4 ln rho`` of the theta inputs ``(p, t)``. [-]
    variance
        GP variances ``1 / tau`` ``(p,)``. [-]
    q_t_trans
        ``Q_t^T`` ``(p, R, R)``.
    l_t, l_x
        Eigenvalues of ``S_theta`` ``(p, R)`` and ``S_x`` ``(p, m*)``.
    w_rot
        ``Q_t^T W Q_x`` ``(p, R, m*)``. [-]
    obs_rot
        ``Q_x^T w*`` ``(p, m*)``. [-]
    ktk
        ``k_j^T k_j`` ``(p,)``. [-]
    prior_a1, prior_b1, prior_const
        Unit-scale prior of each theta* as ``a1 log u + b1 log(1 - u) + const``
        (0, 0, 0 for uniform; Beta(a, b) gives ``a - 1``, ``b - 1``, ``-log B(a, b)``).
    lam_prior, lam_star_prior
        ``(shape, rate)`` of the Gamma priors of ``lambda`` and ``lambda*``.
    """

    theta: FloatArray
    beta_theta: FloatArray
    variance: FloatArray
    q_t_trans: FloatArray
    l_t: FloatArray
    l_x: FloatArray
    w_rot: FloatArray
    obs_rot: FloatArray
    ktk: FloatArray
    prior_a1: FloatArray
    prior_b1: FloatArray
    prior_const: FloatArray
    lam_prior: tuple[float, float]
    lam_star_prior: tuple[float, float]

    @property
    def t(self) -> int:
        """Number of calibration parameters."""
        return int(self.theta.shape[1])

    @property
    def size(self) -> int:
        """Rows of all the stacked ``v_j`` together, ``p (R m* + m*)``."""
        p, n_runs, n_per = self.w_rot.shape
        return p * (n_runs * n_per + n_per)


def _prior_terms(priors: Sequence[Prior]) -> tuple[FloatArray, FloatArray, FloatArray]:
    a1, b1, const = np.zeros(len(priors)), np.zeros(len(priors)), np.zeros(len(priors))
    for k, prior in enumerate(priors):
        if isinstance(prior, BetaPrior):
            a1[k], b1[k] = prior.a - 1.0, prior.b - 1.0
            const[k] = -float(special.betaln(prior.a, prior.b))
        elif not isinstance(prior, UniformPrior):
            raise ConfigError(
                f"sampler 'nuts' supports uniform and beta priors, got {type(prior).__name__}",
                hint="use sampler 'mwg' for other priors",
            )
    return a1, b1, const


def fixed_arrays(target: CalibrationPosterior) -> FixedArrays:
    """Precompute (numpy) what the JAX log posterior of ``target`` needs.

    Parameters
    ----------
    target
        The numpy log posterior; its algebra's data must observe every period.
    """
    d: GridData = target.algebra.data  # type: ignore[attr-defined]
    n_runs, n_per = d.theta.shape[0], d.x.shape[0]
    if d.obs_index.size != n_per or d.w_star is None:
        raise ConfigError(
            f"sampler 'nuts' needs every one of the {n_per} periods observed, "
            f"got {d.obs_index.size}",
            hint="use sampler 'mwg'",
        )
    q_t, l_t, l_x, w_rot, obs_rot = [], [], [], [], []
    for j, kern in enumerate(d.kernels):
        eig_t, eig_x = SymEig.of(kern.theta_cov(d.theta)), SymEig.of(kern.x_corr(d.x))
        w = d.w[:, j].reshape(n_runs, n_per)
        q_t.append(eig_t.vectors.T)
        l_t.append(eig_t.values)
        l_x.append(eig_x.values)
        w_rot.append(eig_t.vectors.T @ (w @ eig_x.vectors))
        obs_rot.append(eig_x.vectors.T @ d.w_star[:, j])
    a1, b1, const = _prior_terms(target.priors)
    return FixedArrays(
        theta=np.asarray(d.theta, dtype=float),
        beta_theta=np.stack([k.beta_theta for k in d.kernels]),
        variance=np.array([k.variance for k in d.kernels]),
        q_t_trans=np.stack(q_t),
        l_t=np.stack(l_t),
        l_x=np.stack(l_x),
        w_rot=np.stack(w_rot),
        obs_rot=np.stack(obs_rot),
        ktk=np.asarray(d.ktk, dtype=float),
        prior_a1=a1,
        prior_b1=b1,
        prior_const=const,
        lam_prior=target.lam_prior,
        lam_star_prior=target.lam_star_prior,
    )


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
    arrays: FixedArrays,
) -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
    """The log posterior in JAX, on the constrained and the unconstrained scale.

    Parameters
    ----------
    arrays
        From :func:`fixed_arrays`.

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
        name: jnp.asarray(getattr(arrays, name))
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
    c |= {"size": float(arrays.size), "lam_prior": arrays.lam_prior}
    c["lam_star_prior"] = arrays.lam_star_prior
    t = arrays.t

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
class NutsChains:
    """Several NUTS chains on the scale they were run on.

    Attributes
    ----------
    position
        Draws after warm-up, ``(chains, draws, d)``.
    logdensity
        The sampled log-density at the draws, ``(chains, draws)``.
    acceptance
        Mean acceptance probability of the NUTS trajectories per chain, ``(chains,)``.
    divergent
        Divergent transitions after warm-up per chain, ``(chains,)``.
    steps
        Mean leapfrog steps (gradient evaluations) per draw per chain, ``(chains,)``.
    step_size
        Adapted step size per chain, ``(chains,)``.
    compile_seconds
        Wall time spent tracing and compiling the JAX programs. [s]
    compile_cpu_seconds
        CPU time of this process spent on the same. [s]
    seconds, cpu_seconds
        Wall and CPU time of the whole run (compilation, warm-up, draws). [s]
    """

    position: FloatArray
    logdensity: FloatArray
    acceptance: FloatArray
    divergent: NDArray[np.int64]
    steps: FloatArray
    step_size: FloatArray
    compile_seconds: float
    compile_cpu_seconds: float
    seconds: float
    cpu_seconds: float


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


def _chain_keys(jax: ModuleType, seed: int, n_chains: int) -> tuple[Any, Any]:
    """Warm-up and sampling keys per chain from ``SeedSequence(seed).spawn(n_chains)``."""
    children = np.random.SeedSequence(seed).spawn(n_chains)
    data = np.stack([c.generate_state(4, np.uint32) for c in children])
    warm = jax.random.wrap_key_data(data[:, :2], impl="threefry2x32")
    sample = jax.random.wrap_key_data(data[:, 2:], impl="threefry2x32")
    return warm, sample


@dataclass
class _Programs:
    """The two jitted NUTS programs, compiled ahead of time on first use (timed)."""

    jax: ModuleType
    warm_fn: Callable[..., Any]
    sample_fn: Callable[..., Any]
    compile_seconds: float = 0.0
    compile_cpu_seconds: float = 0.0
    _warm: Any = None
    _sample: Any = None

    def _compile(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> Any:
        start, cpu = time.perf_counter(), time.process_time()
        compiled = self.jax.jit(fn).lower(*args).compile()
        self.compile_seconds += time.perf_counter() - start
        self.compile_cpu_seconds += time.process_time() - cpu
        return compiled

    def warm(self, *args: Any) -> Any:
        """Warm-up (window adaptation): ``(key, z0) -> (state, params)``."""
        if self._warm is None:
            self._warm = self._compile(self.warm_fn, args)
        return self._warm(*args)

    def sample(self, *args: Any) -> Any:
        """One chunk of draws: ``(state, params, keys) -> (state, outputs)``."""
        if self._sample is None:
            self._sample = self._compile(self.sample_fn, args)
        return self._sample(*args)


def _programs(
    jax: ModuleType,
    blackjax: ModuleType,
    logdensity: Callable[[Any], Any],
    n_burn: int,
    max_num_doublings: int,
    vectorized: bool,
) -> _Programs:
    adapt = blackjax.window_adaptation(
        blackjax.nuts,
        logdensity,
        adaptation_info_fn=blackjax.adaptation.base.get_filter_adapt_info_fn(),
        max_num_doublings=max_num_doublings,
    )

    def warm_one(key: Any, z: Any) -> Any:
        (state, params), _ = adapt.run(key, z, num_steps=n_burn)
        return state, {k: params[k] for k in ("step_size", "inverse_mass_matrix")}

    def sample_one(state: Any, params: Any, keys: Any) -> Any:
        kernel = blackjax.nuts(logdensity, max_num_doublings=max_num_doublings, **params)

        def one(s: Any, key: Any) -> Any:
            s, info = kernel.step(key, s)
            out = (s.position, s.logdensity, info.acceptance_rate, info.is_divergent)
            return s, (*out, info.num_integration_steps)

        return jax.lax.scan(one, state, keys)

    if vectorized:
        return _Programs(jax, jax.vmap(warm_one), jax.vmap(sample_one))
    return _Programs(jax, warm_one, sample_one)


def run_nuts(
    logdensity: Callable[[Any], Any],
    starts: Any,
    n_burn: int,
    n_draws: int,
    seed: int,
    *,
    vectorized: bool = False,
    callback: Callable[[int], None] | None = None,
    max_num_doublings: int = 10,
) -> NutsChains:
    """Window-adapted NUTS chains (diagonal mass matrix) on any unconstrained JAX log-density.

    Parameters
    ----------
    logdensity
        JAX-traceable ``z -> log p(z)`` on ``R^d``.
    starts
        Starting points ``(chains, d)``.
    n_burn
        Warm-up (adaptation) iterations per chain, discarded.
    n_draws
        Kept iterations per chain.
    seed
        Root seed: chain ``k`` uses ``SeedSequence(seed).spawn(chains)[k]``.
    vectorized
        Run the chains as one ``vmap``-ed program instead of one after another
        (slower on 2 CPU cores: it compiles longer, and a vmapped NUTS step
        lasts as long as the longest trajectory among the chains).
    callback
        Progress: called with the iterations completed over all chains.
    max_num_doublings
        Largest NUTS tree depth.
    """
    start, cpu = time.perf_counter(), time.process_time()
    jax, blackjax = require_jax()
    z0 = jax.numpy.asarray(np.asarray(starts, dtype=float))
    n_chains = int(z0.shape[0])
    warm_keys, sample_keys = _chain_keys(jax, seed, n_chains)
    n_chunks = 1 if callback is None else min(10, n_draws)
    chunk = math.ceil(n_draws / n_chunks)
    keys = jax.vmap(lambda k: jax.random.split(k, n_chunks * chunk))(sample_keys)
    keys = keys.reshape(n_chains, n_chunks, chunk)
    progs = _programs(jax, blackjax, logdensity, n_burn, max_num_doublings, vectorized)
    done = _Progress(callback, n_chains, n_burn, n_draws)
    if vectorized:
        outs, step_size = _run_vectorized(progs, warm_keys, z0, keys, done, chunk)
    else:
        outs, step_size = _run_sequential(progs, warm_keys, z0, keys, done)
    z, lp, acc, div, steps = (np.asarray(o)[:, :n_draws] for o in outs)
    return NutsChains(
        position=z,
        logdensity=lp,
        acceptance=acc.mean(axis=1),
        divergent=div.sum(axis=1).astype(np.int64),
        steps=steps.mean(axis=1),
        step_size=step_size,
        compile_seconds=progs.compile_seconds,
        compile_cpu_seconds=progs.compile_cpu_seconds,
        seconds=time.perf_counter() - start,
        cpu_seconds=time.process_time() - cpu,
    )


def _run_vectorized(
    progs: _Programs, warm_keys: Any, z0: Any, keys: Any, done: _Progress, chunk: int
) -> tuple[list[Any], FloatArray]:
    state, params = progs.warm(warm_keys, z0)
    done.burnt_all()
    parts = []
    for i in range(keys.shape[1]):
        state, out = progs.sample(state, params, keys[:, i])
        parts.append([np.asarray(o) for o in out])
        done.drawn_all((i + 1) * chunk)
    outs = [np.concatenate(p, axis=1) for p in zip(*parts, strict=True)]
    return outs, np.asarray(params["step_size"])


def _run_sequential(
    progs: _Programs, warm_keys: Any, z0: Any, keys: Any, done: _Progress
) -> tuple[list[Any], FloatArray]:
    per_chain, sizes = [], []
    for c in range(z0.shape[0]):
        state, params = progs.warm(warm_keys[c], z0[c])
        parts = []
        for i in range(keys.shape[1]):
            state, out = progs.sample(state, params, keys[c, i])
            parts.append([np.asarray(o) for o in out])
        per_chain.append([np.concatenate(p) for p in zip(*parts, strict=True)])
        sizes.append(float(params["step_size"]))
        done.chain_done(c)
    return [np.stack(p) for p in zip(*per_chain, strict=True)], np.array(sizes)


def sample_nuts(
    target: CalibrationPosterior,
    starts: Any,
    n_burn: int,
    n_draws: int,
    seed: int,
    *,
    vectorized: bool = False,
    callback: Callable[[int], None] | None = None,
    max_num_doublings: int = 10,
) -> NutsResult:
    """NUTS on the calibration posterior ``target`` (see the module docstring).

    Parameters
    ----------
    target
        The numpy log posterior (its algebra supplies the fixed arrays).
    starts
        Starting points ``[u, lambda, lambda*]``, ``(chains, t + 2)``, inside the support.
    n_burn, n_draws, seed, vectorized, callback, max_num_doublings
        As :func:`run_nuts`.
    """
    arrays = fixed_arrays(target)
    t = arrays.t
    _, logdensity = jax_log_posterior(arrays)
    chains = run_nuts(
        logdensity,
        to_unconstrained(starts, t),
        n_burn,
        n_draws,
        seed,
        vectorized=vectorized,
        callback=callback,
        max_num_doublings=max_num_doublings,
    )
    z = chains.position
    return NutsResult(to_constrained(z, t), chains.logdensity - log_jacobian(z, t), chains)


@dataclass(frozen=True)
class _Progress:
    """Calls the progress callback with iterations completed over all chains."""

    callback: Callable[[int], None] | None
    n_chains: int
    n_burn: int
    n_draws: int

    def burnt_all(self) -> None:
        if self.callback is not None:
            self.callback(self.n_chains * self.n_burn)

    def drawn_all(self, drawn: int) -> None:
        if self.callback is not None:
            self.callback(self.n_chains * (self.n_burn + min(drawn, self.n_draws)))

    def chain_done(self, chain: int) -> None:
        if self.callback is not None:
            self.callback((chain + 1) * (self.n_burn + self.n_draws))


# ---------------------------------------------------------------- in a spawned process

_QUEUE: Any = None


def _install_queue(queue: Any) -> None:
    global _QUEUE
    _QUEUE = queue


def _child(target: CalibrationPosterior, starts: Any, args: tuple[int, int, int], kw: Any) -> Any:
    callback = None if _QUEUE is None else _QUEUE.put
    n_burn, n_draws, seed = args
    return sample_nuts(target, starts, n_burn, n_draws, seed, callback=callback, **kw)


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
    """:func:`sample_nuts` in a fresh process started with ``spawn``; same draws.

    Once JAX has started its runtime in a process, every later ``os.fork()``
    there (the process pools of the runner and of the MwG chains) risks a
    deadlock and makes JAX emit a ``RuntimeWarning``. Running NUTS in a child
    keeps the caller free of JAX; it costs the child's start-up (importing
    bayescal and JAX, about 2 s) and pickling ``target``.

    Parameters
    ----------
    target, starts, n_burn, n_draws, seed, callback
        As :func:`sample_nuts`; ``callback`` is called in this process.
    **kwargs
        Further keyword arguments of :func:`sample_nuts`.
    """
    check_installed()
    ctx = multiprocessing.get_context("spawn")
    queue = None if callback is None else ctx.Queue()
    with ProcessPoolExecutor(1, ctx, initializer=_install_queue, initargs=(queue,)) as pool:
        future = pool.submit(_child, target, starts, (n_burn, n_draws, seed), kwargs)
        if queue is not None and callback is not None:
            last = 0
            while not future.done():
                last = _drain(queue, callback, 0.2, last)
            last = _drain(queue, callback, 0.0, last)
            total = len(starts) * (n_burn + n_draws)
            if last < total and future.exception() is None:
                callback(total)  # a last tick still in the queue's pipe
        result: NutsResult = future.result()
    return result


def _drain(queue: Any, callback: Callable[[int], None], timeout: float, last: int) -> int:
    """Pass every queued progress count on; the last one seen."""
    try:
        while True:
            last = queue.get(timeout=timeout) if timeout > 0 else queue.get_nowait()
            callback(last)
            timeout = 0.0
    except Empty:
        return last
