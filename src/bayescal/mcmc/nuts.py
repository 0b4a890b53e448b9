"""No-U-Turn sampling with JAX and BlackJAX: the generic engine.

An optional extra (``pip install "bayescal[hmc]"``): JAX and BlackJAX are
imported only when a function here needs them; without them
:func:`require_jax` raises :class:`bayescal.errors.ConfigError` with the
install command (:mod:`bayescal.optional`).

:func:`run_nuts` runs window-adapted NUTS chains (Stan-style adaptation of the
step size and a diagonal inverse mass matrix, BlackJAX's
``window_adaptation``) on any JAX-traceable log-density on ``R^d``. JAX runs
in float64 (``jax_enable_x64`` is switched on for the whole process when JAX
is first used here). By default the chains run one after another: on 2 CPU
cores, vmapping 4 chains into one program sampled about 2x faster but took
about twice as long to compile (~13 instead of ~6.5 CPU s), a loss at
500 + 1000 iterations (benchmarks/bench_hmc.py ``--variants``).

The draws depend on the seed only: the kept iterations are cut into
``min(10, n_draws)`` chunks (one compiled program reused, a progress tick
after each) whether or not anyone watches the progress.

Once JAX has started its runtime in a process, any later ``os.fork()`` there
(the process pools of the runner and of the MwG chains) may deadlock, and JAX
warns about it. :func:`run_isolated` runs a function in a fresh
``spawn``-ed process and relays its progress, so that the caller never starts
JAX; as with any ``spawn``, a script that calls it must guard its top level
with ``if __name__ == "__main__":``.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from queue import Empty
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayescal.errors import ConfigError
from bayescal.optional import install_hint, module_installed

__all__ = [
    "NUTS_MIN_WARMUP",
    "NutsChains",
    "check_installed",
    "require_jax",
    "run_isolated",
    "run_nuts",
]

#: Fewest warm-up iterations window adaptation can work with.
NUTS_MIN_WARMUP = 20

FloatArray = NDArray[np.float64]
INSTALL_HINT = install_hint("jax")


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
    vectorised: bool,
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

    if vectorised:
        return _Programs(jax, jax.vmap(warm_one), jax.vmap(sample_one))
    return _Programs(jax, warm_one, sample_one)


def run_nuts(
    logdensity: Callable[[Any], Any],
    starts: Any,
    n_burn: int,
    n_draws: int,
    seed: int,
    *,
    vectorised: bool = False,
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
    vectorised
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
    n_chunks = min(10, n_draws)  # fixed: the keys (and draws) must not depend on progress
    chunk = math.ceil(n_draws / n_chunks)
    keys = jax.vmap(lambda k: jax.random.split(k, n_chunks * chunk))(sample_keys)
    keys = keys.reshape(n_chains, n_chunks, chunk)
    progs = _programs(jax, blackjax, logdensity, n_burn, max_num_doublings, vectorised)
    done = _Progress(callback, n_chains, n_burn, n_draws)
    if vectorised:
        outs, step_size = _run_vectorised(progs, warm_keys, z0, keys, done, chunk)
    else:
        outs, step_size = _run_sequential(progs, warm_keys, z0, keys, done, chunk)
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


def _run_vectorised(
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
    progs: _Programs, warm_keys: Any, z0: Any, keys: Any, done: _Progress, chunk: int
) -> tuple[list[Any], FloatArray]:
    per_chain, sizes = [], []
    for c in range(z0.shape[0]):
        state, params = progs.warm(warm_keys[c], z0[c])
        done.chain_at(c, 0)
        parts = []
        for i in range(keys.shape[1]):
            state, out = progs.sample(state, params, keys[c, i])
            parts.append([np.asarray(o) for o in out])
            done.chain_at(c, (i + 1) * chunk)
        per_chain.append([np.concatenate(p) for p in zip(*parts, strict=True)])
        sizes.append(float(params["step_size"]))
    return [np.stack(p) for p in zip(*per_chain, strict=True)], np.array(sizes)


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

    def chain_at(self, chain: int, drawn: int) -> None:
        """Chain ``chain`` (earlier ones finished) warmed up and ``drawn`` draws made."""
        if self.callback is not None:
            per_chain = self.n_burn + self.n_draws
            self.callback(chain * per_chain + self.n_burn + min(drawn, self.n_draws))


# ---------------------------------------------------------------- in a spawned process

_QUEUE: Any = None
_DONE = "done"


def _install_queue(queue: Any) -> None:
    global _QUEUE
    _QUEUE = queue


def _child(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    if _QUEUE is None:
        return fn(*args, **kwargs)
    try:
        return fn(*args, callback=_QUEUE.put, **kwargs)
    finally:
        _QUEUE.put(_DONE)  # after every tick: the parent drains up to this marker


def run_isolated(
    fn: Callable[..., Any],
    *args: Any,
    callback: Callable[[int], None] | None = None,
    **kwargs: Any,
) -> Any:
    """``fn(*args, callback=..., **kwargs)`` in a fresh process started with ``spawn``.

    Once JAX has started its runtime in a process, every later ``os.fork()``
    there (the process pools of the runner and of the MwG chains) risks a
    deadlock and makes JAX emit a ``RuntimeWarning``. Running JAX work in a
    child keeps the caller free of JAX; it costs the child's start-up
    (importing bayescal and JAX, about 2 s) and pickling the arguments.

    Parameters
    ----------
    fn
        A module-level function that accepts ``callback=`` (progress counts).
    args, kwargs
        Its arguments (picklable).
    callback
        Called in this process with every progress count the child reports,
        in order, before this function returns.
    """
    check_installed()
    ctx = multiprocessing.get_context("spawn")
    queue = None if callback is None else ctx.Queue()
    with ProcessPoolExecutor(1, ctx, initializer=_install_queue, initargs=(queue,)) as pool:
        future = pool.submit(_child, fn, args, kwargs)
        if queue is not None and callback is not None:
            finished = False
            while not finished and not future.done():
                finished = _drain(queue, callback, 0.2)
            while not finished and future.exception() is None:
                finished = _drain(queue, callback, 5.0)  # the ticks still in the pipe
        return future.result()


def _drain(queue: Any, callback: Callable[[int], None], timeout: float) -> bool:
    """Pass the queued progress counts on; True once the child's end marker arrived."""
    try:
        while True:
            item = queue.get(timeout=timeout)
            if item == _DONE:
                return True
            callback(item)
            timeout = 0.01
    except Empty:
        return False
