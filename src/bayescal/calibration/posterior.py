"""Calibration posterior of theta*, lambda and lambda* (the paper's eq. 16): sample and judge.

With the emulator's hyperparameters fixed at their MAP, the stacked weights
``v_j = [w_j; w*_j]`` are ``N(0, Omega_j)`` (eqs. 12, 14, 17;
:mod:`bayescal.calibration.target`). The sampled vector is ``[u_1 .. u_t,
lambda, lambda*]`` where ``u`` is ``theta*`` on the normalised scale [0, 1] of
the prior bounds; the log posterior adds

* the study priors of ``theta*`` on that scale (uniform, or Beta(a, b) on the
  bounds: :meth:`bayescal.design.Prior.logpdf_unit`);
* ``lambda ~ Gamma`` after eq. 7 (the training data outside the basis);
* ``lambda* ~ Gamma(a + m* (n - p) / 2, b + RSS* / 2)``, eq. 7 applied to the
  measured periods ``Y*``.

The likelihood goes through :class:`bayescal.calibration.kron.KronCalibrationDensity`
(default) or the dense reference. :func:`calibrate` runs ``n_chains`` (>= 4)
adaptive Metropolis-within-Gibbs chains (or, with the optional extra
``bayescal[hmc]``, NUTS chains: :mod:`bayescal.calibration.hmc`) from
dispersed starts and returns a
:class:`Posterior` with draws in physical units, ArviZ ``InferenceData`` and
diagnostics: every R-hat above 1.01, ESS below 400 or stuck chain is listed in
``Posterior.warnings`` (nothing is printed or logged here; the pipeline reports
them).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike

from bayescal.atomic import atomic_write_json, read_json
from bayescal.calibration.hmc import sample_nuts_isolated
from bayescal.calibration.kron import Kind
from bayescal.calibration.target import (
    LAMBDA_NAMES,
    CalibrationPosterior,
    Moves,
    build_target,
    default_starts,
    sample,
)
from bayescal.design import Prior
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.noise import ObservationModel, OutputNoise
from bayescal.errors import ConfigError
from bayescal.mcmc.chains import BACKENDS, ChainBackend, Chains
from bayescal.mcmc.diagnostics import Diagnostics, diagnose, extended_length, import_arviz
from bayescal.mcmc.nuts import NUTS_MIN_WARMUP, check_installed

if TYPE_CHECKING:
    import pandas as pd
    from arviz import InferenceData

__all__ = ["LAMBDA_NAMES", "CalibrationPosterior", "Derived", "Posterior", "calibrate"]

SamplerKind = Literal["mwg", "nuts"]


@dataclass(frozen=True)
class Derived:
    """Draws of a quantity computed from theta* (the wall's U-value, a user's expression).

    Attributes
    ----------
    draws
        ``(chains, draws)``, in ``unit``.
    unit
        Its unit.
    description
        What it is.
    """

    draws: FloatArray
    unit: str = ""
    description: str = ""


@dataclass(frozen=True)
class Posterior:
    """Draws of theta* (physical units), the precisions and error parameters, with diagnostics.

    Attributes
    ----------
    names
        Calibration parameter names ``(t,)``.
    priors
        Parameter name -> prior used in the calibration.
    unit_draws
        theta* on the normalised scale, ``(chains, draws, t)``. [-]
    aux_names
        Names of the other sampled coordinates: ``lambda``, then one
        ``lambda_star`` per output, then one ``phi`` per output with AR(1)
        errors (``("lambda", "lambda_star")`` for the paper's one white output).
    aux
        Their draws ``(chains, draws, k)``. [-]
    log_density
        Log posterior (up to a constant) at the draws ``(chains, draws)``.
    acceptance
        Acceptance rate per chain and coordinate ``(chains, t + k)``.
    seed
        Root seed of the chains.
    algebra
        ``"kronecker"`` or ``"dense"``.
    diagnostics
        R-hat, ESS, MCSE and the list of warnings (over theta* and ``aux``).
    noise
        The outputs' error models (:class:`~bayescal.emulator.noise.OutputNoise`),
        for the noise in physical units; empty where unknown.
    derived
        Quantities computed from theta* at every draw (:meth:`with_derived`).
    """

    names: tuple[str, ...]
    priors: Mapping[str, Prior]
    unit_draws: FloatArray
    aux_names: tuple[str, ...]
    aux: FloatArray
    log_density: FloatArray
    acceptance: FloatArray
    seed: int
    algebra: str
    diagnostics: Diagnostics
    noise: tuple[OutputNoise, ...] = ()
    derived: Mapping[str, Derived] = field(default_factory=dict)

    @classmethod
    def build(
        cls,
        names: Sequence[str],
        priors: Mapping[str, Prior],
        unit_draws: ArrayLike,
        lam: ArrayLike | None = None,
        lam_star: ArrayLike | None = None,
        log_density: ArrayLike = (),
        acceptance: ArrayLike = (),
        seed: int = 0,
        algebra: str = "kronecker",
        sampler_warnings: Sequence[str] = (),
        *,
        aux: ArrayLike | None = None,
        aux_names: Sequence[str] = LAMBDA_NAMES,
        noise: Sequence[OutputNoise] = (),
    ) -> Posterior:
        """Assemble the posterior and compute its diagnostics (physical units).

        Give either ``lam`` and ``lam_star`` (one white output) or ``aux`` with
        its ``aux_names``. ``sampler_warnings`` (e.g. NUTS divergences) are
        appended to the diagnostics' warnings.
        """
        unit = np.asarray(unit_draws, dtype=float)
        if aux is None:
            if lam is None or lam_star is None:
                raise ValueError("give lam and lam_star, or aux")
            aux_arr = np.stack(
                [np.asarray(lam, dtype=float), np.asarray(lam_star, dtype=float)], axis=-1
            )
            aux_names = LAMBDA_NAMES
        else:
            aux_arr = np.asarray(aux, dtype=float)
        if aux_arr.shape[:2] != unit.shape[:2] or aux_arr.shape[-1] != len(aux_names):
            raise ValueError(
                f"aux draws {aux_arr.shape} do not match theta* draws {unit.shape} and "
                f"names {list(aux_names)}"
            )
        phys = np.stack([p.from_unit(unit[..., k]) for k, p in enumerate(priors.values())], axis=-1)
        everything = np.concatenate([phys, aux_arr], axis=-1)
        acc = np.asarray(acceptance, dtype=float)
        diag = diagnose(everything, (*names, *aux_names), acc)
        if sampler_warnings:
            diag = dataclasses.replace(diag, warnings=(*diag.warnings, *sampler_warnings))
        return cls(
            tuple(names),
            dict(priors),
            unit,
            tuple(aux_names),
            aux_arr,
            np.asarray(log_density, dtype=float),
            acc,
            int(seed),
            str(algebra),
            diag,
            tuple(noise),
        )

    @property
    def lam(self) -> FloatArray:
        """Draws of the simulator precision ``lambda`` ``(chains, draws)``. [-]"""
        return self.aux[..., 0]

    @property
    def lam_star(self) -> FloatArray:
        """Draws of the (first output's) observation precision ``lambda*`` ``(chains, draws)``."""
        return self.aux[..., 1]

    @property
    def lam_stars(self) -> FloatArray:
        """Every output's ``lambda*``, ``(chains, draws, O)``."""
        n_out = max(1, len(self.noise))
        return self.aux[..., 1 : 1 + n_out]

    @property
    def phi(self) -> FloatArray:
        """AR(1) coefficients of the outputs with AR(1) errors ``(chains, draws, A)``."""
        n_out = max(1, len(self.noise))
        n_phi = sum(o.model == "ar1" for o in self.noise)
        return self.aux[..., 1 + n_out : 1 + n_out + n_phi]

    @property
    def draws(self) -> FloatArray:
        """theta* in physical units, ``(chains, draws, t)``."""
        cols = [p.from_unit(self.unit_draws[..., k]) for k, p in enumerate(self.priors.values())]
        return np.stack(cols, axis=-1)

    @property
    def warnings(self) -> tuple[str, ...]:
        """Every diagnostic problem found (empty when all checks pass)."""
        return self.diagnostics.warnings

    @cached_property
    def held_names(self) -> tuple[str, ...]:
        """theta* coordinates at one value in every draw: held, not calibrated (``[design]
        reuse_screening``'s screened-out inputs; every one for the catalogue model)."""
        flat = self.unit_draws.reshape(-1, len(self.names))
        return tuple(n for n, r in zip(self.names, np.ptp(flat, axis=0), strict=True) if r == 0)

    @property
    def all_names(self) -> tuple[str, ...]:
        """``names`` then ``aux_names``."""
        return (*self.names, *self.aux_names)

    def all_draws(self) -> FloatArray:
        """``[theta* (physical), aux]``, ``(chains, draws, t + k)``."""
        return np.concatenate([self.draws, self.aux], axis=-1)

    def noise_sd(self) -> dict[str, FloatArray]:
        """Output name -> draws of its noise standard deviation in the output's unit.

        ``s_o / sqrt(lambda*_o)`` with the output's scale ``s_o``; empty where the
        error models are not known (posteriors from before they were recorded).
        """
        return {o.name: o.scale / np.sqrt(self.lam_stars[..., q]) for q, o in enumerate(self.noise)}

    def with_derived(self, derived: Mapping[str, Derived]) -> Posterior:
        """The same posterior with derived quantities attached (names must be new)."""
        clash = sorted(set(derived) & {*self.all_names, *self.derived})
        if clash:
            raise ConfigError(f"derived quantities {clash} clash with names already in use")
        return dataclasses.replace(self, derived={**self.derived, **derived})

    def interval(self, level: float = 0.95) -> tuple[FloatArray, FloatArray]:
        """Central credible interval of theta* per parameter (physical units), ``(t,)`` each."""
        flat = self.draws.reshape(-1, len(self.names))
        tail = 50.0 * (1.0 - level)
        return np.percentile(flat, tail, axis=0), np.percentile(flat, 100.0 - tail, axis=0)

    def summary(self, level: float = 0.95) -> pd.DataFrame:
        """Mean, SD, credible interval, R-hat and ESS per quantity (physical units).

        Rows: the parameters, the sampled precisions and AR(1) coefficients,
        and the noise standard deviation of each output in its unit
        (``noise_sd`` or ``noise_sd_<output>``).
        """
        import pandas as pd

        flat = self.all_draws().reshape(-1, len(self.all_names))
        tail = 50.0 * (1.0 - level)
        table = pd.DataFrame(self.diagnostics.table())
        table["lower"] = np.percentile(flat, tail, axis=0)
        table["upper"] = np.percentile(flat, 100.0 - tail, axis=0)
        extras = {
            ("noise_sd" if len(self.noise) == 1 else f"noise_sd_{n}"): sd
            for n, sd in self.noise_sd().items()
        }
        extras |= {name: d.draws for name, d in self.derived.items()}
        if extras:
            stacked = np.stack(list(extras.values()), axis=-1)
            extra = pd.DataFrame(diagnose(stacked, list(extras)).table())
            flat_extra = stacked.reshape(-1, len(extras))
            extra["lower"] = np.percentile(flat_extra, tail, axis=0)
            extra["upper"] = np.percentile(flat_extra, 100.0 - tail, axis=0)
            table = pd.concat([table, extra])
        return table

    def inference_data(self) -> InferenceData:
        """ArviZ ``InferenceData``: posterior (physical theta*, aux), lp, seed."""
        az = import_arviz()
        draws = self.all_draws()
        posterior = {n: draws[..., k] for k, n in enumerate(self.all_names)}
        return az.from_dict(
            posterior=posterior,
            sample_stats={"lp": self.log_density},
            attrs={"seed": self.seed, "algebra": self.algebra},
        )


def check_priors(assembled: Assembled, priors: Mapping[str, Prior] | None) -> dict[str, Prior]:
    if priors is None:
        return dict(assembled.priors)
    if tuple(priors) != assembled.parameter_names:
        raise ConfigError(
            f"calibration priors are given for {list(priors)}, the design has "
            f"{list(assembled.parameter_names)} (same names, same order)"
        )
    for name, prior in priors.items():
        ref = assembled.priors[name]
        if (prior.lower, prior.upper) != (ref.lower, ref.upper):
            raise ConfigError(
                f"prior of {name!r} has bounds [{prior.lower}, {prior.upper}], the design "
                f"was drawn on [{ref.lower}, {ref.upper}]",
                hint="keep the design's bounds; change only the shape (uniform or beta)",
            )
    return dict(priors)


def calibrate(
    emulator: Emulator,
    assembled: Assembled,
    priors: Mapping[str, Prior] | None = None,
    *,
    n_chains: int = 4,
    n_burn: int = 1000,
    n_draws: int = 1000,
    seed: int = 0,
    backend: ChainBackend = "auto",
    algebra: Kind = "kronecker",
    sampler: SamplerKind = "mwg",
    callback: Callable[[int], None] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
    observations: ObservationModel | None = None,
    moves: Moves = "gibbs",
    max_draws: int | None = None,
    on_extend: Callable[[int, int], Callable[[int], None] | None] | None = None,
    held: Mapping[str, float] | None = None,
    starts: ArrayLike | None = None,
    fixed: Mapping[str, float] | None = None,
) -> Posterior:
    """Sample theta*, lambda and lambda* (eq. 16) with the hyperparameters at the MAP.

    Parameters
    ----------
    emulator
        The trained emulator (its kernels, weights and ``lambda`` prior).
    assembled
        The assembled data (measured weights ``W*`` and the ``lambda*`` prior).
    priors
        Parameter name -> prior on the design's bounds (default: the design's).
    n_chains
        Number of chains; diagnostics warn below 4.
    n_burn, n_draws
        Burn-in (adapted, discarded) and kept iterations per chain.
    seed
        Root seed; chain ``k`` uses ``SeedSequence(seed).spawn(n_chains)[k]``.
    backend
        ``"auto"`` (default: lockstep groups over the worker processes where the
        batched likelihood exists, else worker processes; see
        :func:`bayescal.mcmc.chains.choose_backend`), ``"processes"`` (chains in
        worker processes), ``"serial"``, ``"vectorised"`` (all chains in
        lockstep in this process, one batched likelihood call per coordinate
        update; ``sampler="mwg"`` only; draws equal the serial ones; see
        ``docs/benchmarks.md``) or ``"vectorised-processes"``.
    algebra
        ``"kronecker"`` (fast, default) or ``"dense"`` (reference).
    sampler
        ``"mwg"`` (Metropolis-within-Gibbs) or ``"nuts"`` (No-U-Turn sampler with window adaptation,
        :func:`bayescal.calibration.hmc.sample_nuts`; needs the extra
        ``bayescal[hmc]`` and ``algebra="kronecker"``). With ``"nuts"``
        ``n_burn`` is the warm-up length, the chains run one after another in
        one spawned process whatever ``backend`` says (JAX never starts in
        this one, so later process pools may fork safely), the acceptance columns all
        hold each chain's mean NUTS acceptance probability, divergent
        transitions are added to the warnings, and ``checkpoint_dir`` is
        ignored (a killed NUTS run starts again from the beginning).
    callback
        Progress: called with the iterations completed over all chains.
    checkpoint_dir
        Folder for per-chain snapshots; a killed run resumes from them with
        identical draws (see :func:`bayescal.mcmc.chains.run_chains`).
        Not supported by ``"nuts"`` (ignored).
    checkpoint_seconds
        Minimum wall time between two snapshots of a chain. [s]
    observations
        The outputs' error models (:mod:`bayescal.emulator.noise`: one
        ``lambda*`` per output, AR(1) errors); default: the paper's one white
        output with ``assembled.lam_star_prior``. NUTS needs one white output.
    moves
        ``"gibbs"`` (default) or ``"joint"``: how the ``"mwg"`` sweeps move the
        coordinates after burn-in (:func:`bayescal.calibration.target.default_sampler`).
    max_draws
        Length by convergence (``"mwg"`` only): while a diagnostic fails (R-hat
        above 1.01, bulk or tail ESS below 400, a stuck chain), the chains are
        extended by half their kept length at a time, at most to ``max_draws``
        kept draws per chain. Each extension resumes the chains' last snapshots
        (in ``checkpoint_dir``, else a temporary folder), so no sweep is redone:
        the extended chains are those that ran, continued with their proposal
        widths as burn-in left them. ``None`` (default): ``n_draws`` exactly.
    on_extend
        Called as ``on_extend(kept, longer)`` before each extension; it may
        return a new progress callback for the extension (else ``callback``
        keeps counting).
    held
        Every parameter name -> a value (physical units) to hold theta* at
        (``"mwg"`` only; :func:`bayescal.calibration.target.hold_theta`): the
        chains sample the error model's parameters alone and the draws of
        theta* all equal these values (the catalogue model of ``bayescal
        compare``: the nominal values). ``None`` (default): theta* is sampled.
    starts
        Where the chains' theta* start, ``(n_chains, t)`` on the normalised
        scale [0, 1] of the bounds (e.g. draws of a previous posterior:
        :func:`bayescal.pipeline.sequential.warm_starts`); a NaN entry keeps
        the default start of that coordinate. Values are clipped into
        ``[START_MARGIN, 1 - START_MARGIN]``, inside every prior's support. The
        precisions (and AR(1) coefficients, discrepancy variances) start as by
        default. ``None`` (default): dispersed starts (:func:`default_starts`).
    fixed
        Some parameters -> a value (physical units) each is held at (``"mwg"``
        only), the others sampled: the emulator's inputs that are not
        calibrated (``[design] reuse_screening``, :mod:`bayescal.pipeline.reuse`).
        Their draws all equal these values. Not with ``held``.

    Returns
    -------
    Posterior
    """
    if backend not in BACKENDS:
        raise ConfigError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
    if sampler not in ("mwg", "nuts"):
        raise ConfigError(f"sampler must be 'mwg' or 'nuts', got {sampler!r}")
    if (held is not None or fixed) and sampler != "mwg":
        raise ConfigError("theta* can be held fixed with sampler 'mwg' only")
    if held is not None and fixed:
        raise ConfigError("hold every parameter (held) or some (fixed), not both")
    if sampler == "nuts":
        check_installed()
        if n_burn < NUTS_MIN_WARMUP:
            raise ConfigError(
                f"sampler 'nuts' adapts its step size during the burn-in: got {n_burn} "
                f"iterations, expected at least {NUTS_MIN_WARMUP}",
                hint="set [calibration] burn = 500",
            )
        if algebra != "kronecker":
            raise ConfigError(
                f"sampler 'nuts' evaluates eq. 16 by the Kronecker route in JAX, got "
                f"algebra {algebra!r}",
                hint="set [emulator] algebra = 'kronecker' or use sampler 'mwg'",
            )
    prior_map = check_priors(assembled, priors)
    hold, hold_at = _holding(held, fixed, prior_map)
    target = build_target(
        emulator,
        assembled.w_star,
        assembled.lam_star_prior,
        list(prior_map.values()),
        algebra=algebra,
        observations=observations,
    )
    if sampler == "nuts" and not target.plain:
        raise ConfigError(
            "sampler 'nuts' samples one output with white errors; this calibration has "
            f"{target.prior_terms.n_outputs} output(s) and {target.prior_terms.n_phi} AR(1) "
            "coefficient(s)",
            hint="use sampler 'mwg'",
        )
    x0 = warm(default_starts(target, n_chains, seed), starts, target.t)
    if sampler == "nuts":
        return _calibrate_nuts(
            target, x0, prior_map, assembled.parameter_names, n_burn, n_draws, seed, callback
        )
    names = (*assembled.parameter_names, *target.aux_names)

    def run_once(kept: int, folder: str | os.PathLike[str] | None, report: Callback) -> Posterior:
        chains = sample(
            target,
            kept,
            n_burn=n_burn,
            n_chains=n_chains,
            seed=seed,
            backend=backend,
            names=names,
            callback=report,
            checkpoint_dir=folder,
            checkpoint_seconds=checkpoint_seconds,
            starts=x0,
            moves=moves,
            held=hold,
            held_at=hold_at,
        )
        return _built(chains, target, prior_map, assembled, seed, algebra, observations)

    plan: dict[str, object] = {"n_burn": n_burn, "n_chains": n_chains, "seed": int(seed)}
    return until_converged(
        run_once,
        n_draws,
        max_draws,
        plan | {"moves": moves},
        checkpoint_dir=checkpoint_dir,
        callback=callback,
        on_extend=on_extend,
    )


Callback = Callable[[int], None] | None


def until_converged(
    run_once: Callable[[int, str | os.PathLike[str] | None, Callback], Posterior],
    n_draws: int,
    max_draws: int | None,
    plan: dict[str, object],
    *,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    callback: Callback = None,
    on_extend: Callable[[int, int], Callable[[int], None] | None] | None = None,
) -> Posterior:
    """Chains of ``n_draws`` kept draws, extended while a diagnostic fails (``max_draws``).

    ``run_once(kept, checkpoint_dir, callback)`` runs the chains to ``kept`` kept
    draws (resuming their snapshots in ``checkpoint_dir``) and judges them. While
    the posterior's diagnostics fail and fewer than ``max_draws`` are kept, the
    chains are extended by half their kept length at a time (``on_extend(kept,
    longer)`` first; it may return a new progress callback). The length being
    reached is written beside the snapshots with ``plan`` (what else fixes the
    draws), so a killed run with the same plan goes straight to it
    (:func:`calibrate`'s ``max_draws``).
    """
    most = n_draws if max_draws is None else int(max_draws)
    if most < n_draws:
        raise ConfigError(f"max_draws must be >= n_draws = {n_draws}, got {most}")
    with ExitStack() as stack:
        if most > n_draws and checkpoint_dir is None:
            checkpoint_dir = stack.enter_context(TemporaryDirectory(prefix="bayescal-chains-"))
        plan = plan | {"n_draws": n_draws, "max_draws": most}
        kept = _extended_length(checkpoint_dir, plan, n_draws, most) or n_draws
        while True:
            post = run_once(kept, checkpoint_dir, callback)
            if post.diagnostics.ok or kept >= most:
                return post
            longer = extended_length(kept, most)
            if on_extend is not None:
                callback = on_extend(kept, longer) or callback
            assert checkpoint_dir is not None  # a temporary folder where none was given
            atomic_write_json(Path(checkpoint_dir) / EXTENSION_FILE, plan | {"kept": longer})
            kept = longer


def _holding(
    held: Mapping[str, float] | None,
    fixed: Mapping[str, float] | None,
    priors: Mapping[str, Prior],
) -> tuple[FloatArray | None, list[int] | None]:
    """The held values on the normalised scale and their coordinates (None: all or none)."""
    if held is not None:
        return _held_unit(held, priors), None
    if not fixed:
        return None, None
    unknown = sorted(set(fixed) - set(priors))
    if unknown:
        raise ConfigError(
            f"cannot hold {unknown}: the calibration has {list(priors)}",
            hint="hold only parameters of the calibration",
        )
    names = [name for name in priors if name in fixed]
    unit = np.array([float(priors[name].to_unit(fixed[name])) for name in names])
    outside = [name for name, u in zip(names, unit, strict=True) if not 0.0 <= u <= 1.0]
    if outside:
        p = priors[outside[0]]
        raise ConfigError(
            f"the held value {fixed[outside[0]]:g} of {outside[0]} lies outside its prior "
            f"[{p.lower:g}, {p.upper:g}]",
            hint="hold it at a value inside the prior's bounds",
        )
    return unit, [list(priors).index(name) for name in names]


def _held_unit(held: Mapping[str, float], priors: Mapping[str, Prior]) -> FloatArray:
    """The held values on the normalised scale, in the priors' order."""
    if set(held) != set(priors):
        raise ConfigError(
            f"hold every parameter or none: got {sorted(held)}, the calibration has {list(priors)}"
        )
    unit = np.array([float(p.to_unit(held[name])) for name, p in priors.items()])
    outside = [name for name, u in zip(priors, unit, strict=True) if not 0.0 <= u <= 1.0]
    if outside:
        raise ConfigError(f"the held value of {outside[0]} lies outside its prior bounds")
    return unit


#: How far inside [0, 1] given starts are clipped (a prior's density may vanish on the bounds).
START_MARGIN = 1e-6


def warm(default: FloatArray, starts: ArrayLike | None, t: int) -> FloatArray:
    """The starting points ``default`` with theta* (its first ``t`` columns) replaced by
    ``starts`` where given: ``(chains, t)`` on the normalised scale; NaN keeps the default.
    """
    if starts is None:
        return default
    given = np.asarray(starts, dtype=float)
    n_chains = default.shape[0]
    if given.shape != (n_chains, t):
        raise ConfigError(
            f"starts must be (chains, t) = ({n_chains}, {t}) on the normalised scale, "
            f"got shape {given.shape}"
        )
    out = default.copy()
    clipped = np.clip(given, START_MARGIN, 1.0 - START_MARGIN)
    out[:, :t] = np.where(np.isnan(given), default[:, :t], clipped)
    return out


EXTENSION_FILE = "extension.json"
"""Beside the chains' snapshots: the length a calibration was being extended to."""


def _extended_length(
    folder: str | os.PathLike[str] | None, plan: dict[str, object], least: int, most: int
) -> int | None:
    """The length a killed calibration with the same plan was being extended to.

    The rounds before it failed their diagnostics with draws that depend on the seed
    only, so a resumed calibration goes straight to that length (its snapshots hold
    the sweeps already done) instead of repeating the rounds and their checks.
    """
    if folder is None:
        return None
    try:
        found = read_json(Path(folder) / EXTENSION_FILE)
    except (OSError, ValueError):
        return None
    if not isinstance(found, dict) or {k: found.get(k) for k in plan} != plan:
        return None
    kept = found.get("kept")
    return kept if isinstance(kept, int) and least <= kept <= most else None


def _built(
    chains: Chains,
    target: CalibrationPosterior,
    prior_map: dict[str, Prior],
    assembled: Assembled,
    seed: int,
    algebra: Kind,
    observations: ObservationModel | None,
) -> Posterior:
    """The posterior of the ``"mwg"`` chains of :func:`calibrate`, with its diagnostics."""
    draws = chains.draws
    t = target.t
    return Posterior.build(
        names=assembled.parameter_names,
        priors=prior_map,
        unit_draws=draws[..., :t],
        log_density=chains.log_density,
        acceptance=chains.acceptance,
        seed=int(seed),
        algebra=algebra,
        aux=draws[..., t:],
        aux_names=target.aux_names,
        noise=() if observations is None else observations.outputs,
    )


def _calibrate_nuts(
    target: CalibrationPosterior,
    starts: FloatArray,
    prior_map: dict[str, Prior],
    names: Sequence[str],
    n_burn: int,
    n_draws: int,
    seed: int,
    callback: Callable[[int], None] | None,
) -> Posterior:
    """The ``sampler="nuts"`` branch of :func:`calibrate`."""
    result = sample_nuts_isolated(target, starts, n_burn, n_draws, seed, callback=callback)
    t = target.t
    acceptance = np.repeat(result.chains.acceptance[:, None], t + 2, axis=1)
    divergences = [
        f"chain {c} had {n} divergent NUTS transitions after warm-up; the posterior may be "
        "biased: lengthen the warm-up ([calibration] burn) or use sampler 'mwg'"
        for c, n in enumerate(result.chains.divergent)
        if n > 0
    ]
    return Posterior.build(
        names=names,
        priors=prior_map,
        unit_draws=result.draws[..., :t],
        lam=result.draws[..., t],
        lam_star=result.draws[..., t + 1],
        log_density=result.log_density,
        acceptance=acceptance,
        seed=int(seed),
        algebra="kronecker",
        sampler_warnings=divergences,
    )
