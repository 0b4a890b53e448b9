"""A joint random-walk move of a few correlated coordinates, added to each Gibbs sweep.

Metropolis-within-Gibbs moves one coordinate at a time. When the posterior
of some coordinates is a narrow ridge (a wall's insulation and brick
conductivities when only the total resistance is measured; a box's wall
conductivity and window resistance, which both set the heat loss), each
one-coordinate step is as short as the ridge is narrow and the chain crawls
along it. After the coordinate updates of every sweep, the coordinates of
the *joint block* ``J`` then also move together:

    z_J' = z_J + L e,   e ~ N(0, I),   L L^T = exp(2 g) (2.38^2 / |J|) C,

on the sampling scale, accepted by Metropolis with the Jacobians of the
bounded coordinates. During burn-in ``C`` is the empirical covariance of
``z_J`` (Haario, Saksman & Tamminen 2001) with ``1e-9 mean(diag C)`` added to
its diagonal, estimated in two windows as Stan's warm-up does: over the second
quarter of burn-in, then afresh over its second half (the first window still
holds the chains' way in from dispersed starts; the second sees the target
only). A window's estimate is used once it has ``2 |J| + 10`` sweeps; before
the first, ``C`` is the diagonal of the coordinates' own proposal widths
squared divided by 2.4^2 (their conditional spread).
``g`` moves by the same Roberts–Rosenthal step as the widths towards the
acceptance rate 0.234 (Roberts, Gelman & Gilks 1997). After burn-in ``L`` is
frozen, so the kept draws come from a fixed reversible kernel (a composition
of Metropolis kernels that each leave the target invariant).

The same functions serve one chain (:mod:`.mwg`) and chains in lockstep
(:mod:`.lockstep`), so that both take the same float operations and draws.

With ``screen`` (delayed acceptance, Christen & Fox 2005) a joint proposal is
first tested against a cheap stand-in ``q`` of the block's posterior on the
sampling scale: it goes on with probability ``min(1, q(z_J') / q(z_J))``, and
only then is the log-density evaluated and the proposal accepted with
probability ``min(1, pi(z') q(z_J) / (pi(z) q(z_J')))``. The two stages
together leave the target invariant whatever ``q`` is (a poor stand-in costs
mixing, never exactness); where ``q`` is close to the block's posterior, most
proposals that would be rejected are turned down without an evaluation. ``q``
is a Student-t with 4 degrees of freedom around the current window's mean
``m``, its scale matrix ``1.5^2 C``. Both choices keep ``q``'s tails heavier
than the target's: where ``pi / q`` grows into a tail, a chain that gets there
stays (every way back is turned down at the second stage), as an independence
sampler with a light-tailed proposal does. On the Twin House calibration a
Gaussian ``N(m, C)`` did exactly that (bulk ESS 37, R-hat 1.08 where the
unscreened chains reach 808): a burn-in window's ``C`` comes out narrower than
the posterior (there, 30 % narrower SDs). The screen is used once the current
window holds ``min_samples`` sweeps; after burn-in ``m`` and ``C`` are frozen
with the kernel.

References: H. Haario, E. Saksman, J. Tamminen (2001), "An adaptive Metropolis
algorithm", Bernoulli 7(2), 223-242; G. O. Roberts, A. Gelman, W. R. Gilks
(1997), Ann. Appl. Probab. 7(1), 110-120; J. A. Christen, C. Fox (2005),
"Markov chain Monte Carlo using an approximation", J. Comput. Graph. Stat.
14(4), 795-810.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bayescal.mcmc.samplers.base import ScalarMap

FloatArray = NDArray[np.float64]

#: Target acceptance rate of the joint move.
JOINT_TARGET = 0.234
#: Haario's scaling of the proposal covariance, ``2.38^2 / |J|``.
HAARIO = 2.38**2
#: The screen's stand-in: a Student-t of ``SCREEN_DOF`` degrees of freedom around the
#: window's mean with ``SCREEN_SCALE^2`` times the covariance estimate (module docstring).
SCREEN_SCALE = 1.5
SCREEN_DOF = 4.0


def min_samples(n_joint: int) -> int:
    """Burn-in sweeps collected before the empirical covariance replaces the diagonal."""
    return 2 * n_joint + 10


@dataclass
class JointState:
    """One chain's joint move: proposal factor, covariance estimate and counts.

    Attributes
    ----------
    log_g
        Log of the extra proposal scale ``g``.
    n, mean, m2
        Welford accumulators of ``z_J`` over the current window's sweeps.
    chol
        Current proposal factor ``L`` ``(|J|, |J|)``.
    cov
        The last usable covariance estimate (zeros before the first).
    accepted
        Accepted joint moves since the last reset.
    screened
        Joint proposals the screen turned down since the last reset.
    """

    log_g: float
    n: int
    mean: FloatArray
    m2: FloatArray
    chol: FloatArray
    cov: FloatArray
    accepted: int = 0
    screened: int = 0

    @classmethod
    def start(cls, widths: FloatArray) -> JointState:
        """The state before any adaptation, from the coordinates' proposal widths."""
        k = widths.size
        zeros = np.zeros((k, k))
        return cls(0.0, 0, np.zeros(k), zeros, _diagonal_factor(widths, 0.0), zeros.copy())

    def restart(self) -> None:
        """Open a new estimation window (the last estimate stays in use until replaced)."""
        k = self.mean.size
        self.n, self.mean, self.m2 = 0, np.zeros(k), np.zeros((k, k))

    def collect(self, z_joint: FloatArray) -> None:
        """Add one burn-in sweep's ``z_J`` to the covariance estimate (Welford)."""
        self.n += 1
        delta = z_joint - self.mean
        self.mean = self.mean + delta / self.n
        self.m2 = self.m2 + np.outer(delta, z_joint - self.mean)

    def adapt(self, moves: int, step: float, widths: FloatArray) -> None:
        """After a burn-in batch of ``moves`` joint moves: move ``g``, rebuild ``L``."""
        self.log_g += step if self.accepted > JOINT_TARGET * moves else -step
        k = widths.size
        if self.n >= min_samples(k):
            cov = self.m2 / (self.n - 1)
            self.cov = cov + 1e-9 * float(np.mean(np.diag(cov))) * np.eye(k)
        if np.any(self.cov):
            try:
                self.chol = np.asarray(
                    np.linalg.cholesky(math.exp(2.0 * self.log_g) * HAARIO / k * self.cov),
                    dtype=float,
                )
                return
            except np.linalg.LinAlgError:
                pass
        self.chol = _diagonal_factor(widths, self.log_g)

    def arrays(self, prefix: str = "joint_") -> dict[str, Any]:
        """The state as arrays for a snapshot."""
        scalars = np.array([self.log_g, self.n, self.accepted, self.screened], dtype=float)
        return {
            f"{prefix}scalars": scalars,
            f"{prefix}mean": self.mean,
            f"{prefix}m2": self.m2,
            f"{prefix}chol": self.chol,
            f"{prefix}cov": self.cov,
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], prefix: str = "joint_") -> JointState:
        """The state written by :meth:`arrays`."""
        log_g, n, accepted, screened = np.asarray(arrays[f"{prefix}scalars"], dtype=float).tolist()
        return cls(
            float(log_g),
            int(n),
            np.array(arrays[f"{prefix}mean"], dtype=float),
            np.array(arrays[f"{prefix}m2"], dtype=float),
            np.array(arrays[f"{prefix}chol"], dtype=float),
            np.array(arrays[f"{prefix}cov"], dtype=float),
            int(accepted),
            int(screened),
        )


def _diagonal_factor(widths: FloatArray, log_g: float) -> FloatArray:
    """``L`` from the coordinates' own widths (conditional spread ~ width / 2.4)."""
    k = widths.size
    sd = widths / 2.4 * math.sqrt(math.exp(2.0 * log_g) * HAARIO / k)
    return np.diag(sd)


def collecting(n_done: int, n_burn: int) -> bool:
    """Whether the sweep after ``n_done`` adds to the covariance estimate."""
    return n_burn // 4 <= n_done < n_burn


def restarting(n_done: int, n_burn: int) -> bool:
    """Whether the sweep after ``n_done`` opens the second estimation window."""
    return n_done == n_burn // 2


def joint_only(n_done: int, n_burn: int, joint_after_burn: int) -> bool:
    """Whether the sweep after ``n_done`` moves the block's coordinates only jointly.

    With ``joint_after_burn = k > 0``, from the second estimation window of
    burn-in on (:func:`restarting`): the window then learns the covariance from
    the joint moves, which mix far better than one-coordinate steps where the
    block is correlated, and the adaptation of ``g`` sees the kernel that is
    kept after burn-in.
    """
    return joint_after_burn > 0 and n_done >= n_burn // 2


def batch_moves(n_done: int, size: int, n_burn: int, joint_after_burn: int) -> tuple[bool, int]:
    """Of the ``size`` sweeps after ``n_done``: whether the last moves the block only
    jointly (its coordinates' own widths then stay as they are) and the joint moves
    made in all (what the adaptation of ``g`` counts acceptances against)."""
    moves = sum(
        joint_after_burn if joint_only(n, n_burn, joint_after_burn) else 1
        for n in range(n_done, n_done + size)
    )
    return joint_only(n_done + size - 1, n_burn, joint_after_burn), moves


def screen_precision(js: JointState) -> FloatArray | None:
    """The stand-in's precision ``C^-1`` (``None``: no estimate yet, or a singular one)."""
    if not np.any(js.cov):
        return None
    try:
        return np.asarray(np.linalg.inv(js.cov), dtype=float)
    except np.linalg.LinAlgError:
        return None


def screen_in_use(js: JointState, precision: FloatArray | None) -> FloatArray | None:
    """``precision`` where this sweep screens (an estimate exists and the current
    window's mean has ``min_samples`` sweeps), else ``None``."""
    if precision is None or js.n < min_samples(js.mean.size):
        return None
    return precision


def screen_log_ratio(
    z_new: FloatArray, z_old: FloatArray, mean: FloatArray, precision: FloatArray
) -> float:
    """``log q(z_new) - log q(z_old)`` of the stand-in ``q``: a Student-t (``SCREEN_DOF``)
    around ``mean`` with scale matrix ``SCREEN_SCALE^2 precision^-1``."""
    a, b = z_new - mean, z_old - mean
    scale = SCREEN_SCALE**2 * SCREEN_DOF
    qa, qb = float(a @ precision @ a) / scale, float(b @ precision @ b) / scale
    return -0.5 * (SCREEN_DOF + mean.size) * (math.log1p(qa) - math.log1p(qb))


def screened_share(js: JointState, n_draws: int, thin: int, joint_after_burn: int) -> float:
    """Share of the joint proposals after burn-in the screen turned down unseen."""
    return js.screened / (n_draws * thin * max(1, joint_after_burn))


def propose(z_joint: FloatArray, chol: FloatArray, eps: FloatArray) -> FloatArray:
    """``z_J + L e`` (one chain)."""
    out: FloatArray = z_joint + chol @ eps
    return out


def log_ratio(lp_new: float, lj_new: list[float], lp: float, lj_old: list[float]) -> float:
    """Metropolis log ratio with the Jacobians of the moved coordinates (fixed order)."""
    return lp_new + math.fsum(lj_new) - lp - math.fsum(lj_old)


def map_values(
    maps: Sequence[ScalarMap | None], joint: Sequence[int], z_new: NDArray[np.float64]
) -> tuple[list[float], list[float]] | None:
    """Original values and log-Jacobians of one chain's joint proposal; ``None`` on overflow."""
    values, jacobians = [], []
    for k, i in enumerate(joint):
        f, v = maps[i], float(z_new[k])
        if f is None:
            values.append(v)
            jacobians.append(0.0)
            continue
        try:
            xi, lji = f(v)
        except OverflowError:
            return None
        values.append(xi)
        jacobians.append(lji)
    return values, jacobians


__all__ = [
    "JOINT_TARGET",
    "JointState",
    "batch_moves",
    "collecting",
    "joint_only",
    "log_ratio",
    "map_values",
    "min_samples",
    "propose",
    "screen_in_use",
    "screen_log_ratio",
    "screen_precision",
    "screened_share",
]
