"""``bayescal joint A B ... --out DIR``: finished studies of several records calibrated together.

Each study keeps what it built on its own record (design, runs, basis,
emulator, error model); their likelihoods are multiplied with the shared
parameters' prior counted once (:mod:`bayescal.calibration.joint`). The
parameters are matched by name; a shared one must have the same prior in every
study, and no study may take its prior from another's posterior (``[study]
prior_from``: its data would count twice).

The result is the joint posterior beside each study's own: ``posterior.nc``,
``joint-summary.csv`` (every parameter, each study alone and jointly),
``joint.png`` (their marginal densities) and ``joint.md`` (the table, its warnings
first) in ``--out``. Warnings say what a
joint posterior hides: a parameter whose joint posterior lies outside what one
record alone allows (the records disagree: a model error in one of them at
least), one leaning on a prior bound, a failed diagnostic.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from bayescal.atomic import atomic_write_text
from bayescal.calibration.bounds import bound_warnings
from bayescal.calibration.joint import JointPosterior, Record, calibrate_joint
from bayescal.calibration.posterior import Derived, Posterior
from bayescal.calibration.target import Moves, build_target
from bayescal.config import Study, load_study
from bayescal.design import Prior
from bayescal.errors import ConfigError
from bayescal.pipeline.keys import keys_and_inputs
from bayescal.pipeline.run import Results, load_results, writing
from bayescal.pipeline.stages import Context, Options, derived_at, prepare
from bayescal.report.joint import joint_markdown, plot_joint
from bayescal.store import emulator as emulator_store
from bayescal.store import posterior as posterior_store
from bayescal.store.stages import StageLog

__all__ = ["JointResult", "joint", "joint_priors", "label_of"]

SUMMARY_FILE = "joint-summary.csv"
FIGURE_FILE = "joint.png"
MARKDOWN_FILE = "joint.md"
JOINT = "joint"


@dataclass(frozen=True)
class JointResult:
    """A joint calibration and what it says.

    Attributes
    ----------
    posterior
        The joint posterior (theta* in physical units, each record's error parameters).
    summary
        One row per parameter and source (each study alone, then ``joint``):
        mean, SD and the 95 % interval.
    labels
        The studies' names, in the order given.
    files
        What was written into the output folder.
    warnings
        What the user must read first.
    notes
        What the joint calibration leaves out or holds (also in ``joint.md``).
    seconds
        Wall time of the chains. [s]
    """

    posterior: Posterior
    summary: pd.DataFrame
    labels: tuple[str, ...]
    files: tuple[Path, ...]
    warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = field(default=())
    seconds: float = 0.0


def _prepared(path: Path) -> Context:
    study = load_study(path)
    if study.study.prior_from is not None:
        raise ConfigError(
            f"{path}: its prior comes from the posterior of {study.study.prior_from} "
            "([study] prior_from), so a joint calibration would count those data twice",
            hint="give the joint calibration the study without prior_from, and the other "
            "record as a study of its own",
        )
    return prepare(study)


def _finished(ctx: Context) -> Results:
    """The study's results, its emulator and calibration up to date with its file."""
    res = load_results(ctx.study)
    path = ctx.study.path
    if res.emulator is None or res.posterior is None:
        raise ConfigError(
            f"{path}: the study has no finished calibration (a joint calibration uses each "
            "study's emulator and compares with its own posterior)",
            hint=f"run `bayescal run {path}` first",
        )
    log = StageLog.open(ctx.out)
    keys, inputs = keys_and_inputs(ctx)
    for stage in ("emulator", "calibrate"):
        if not log.done(stage, keys[stage]):
            changed = log.changed_inputs(stage, keys[stage], inputs[stage]) or ["an input"]
            raise ConfigError(
                f"{path}: the study changed since its {stage} stage ran ({', '.join(changed)} "
                "changed), so its emulator and posterior are not those of the study file",
                hint=f"run `bayescal run {path}` to bring it up to date",
            )
    return res


def _same_prior(name: str, first: tuple[str, Prior], other: tuple[str, Prior]) -> None:
    (a, pa), (b, pb) = first, other
    if pa.spec() != pb.spec() or pa.unit != pb.unit:
        raise ConfigError(
            f"{name} has the prior {pa.spec()} [{pa.unit}] in {a} but {pb.spec()} [{pb.unit}] "
            f"in {b}: a shared parameter's prior counts once, so it must be the same",
            hint=f"give {name} the same prior in every study, then `bayescal run` the one changed",
        )


def joint_priors(contexts: Sequence[Context]) -> dict[str, Prior]:
    """The joint posterior's parameters and priors: every study's calibrated ones, in
    order of first appearance; raises where the studies cannot be calibrated together
    (a name twice, no shared parameter, a shared one with different priors)."""
    labels = [label_of(ctx) for ctx in contexts]
    twice = sorted({x for x in labels if labels.count(x) > 1})
    if twice:
        raise ConfigError(
            f"two studies are named {twice[0]!r}: the joint posterior names each record's "
            "error parameters after its study",
            hint="give each study its own [study] name",
        )
    priors: dict[str, Prior] = {}
    owner: dict[str, str] = {}
    count: dict[str, int] = {}
    for label, ctx in zip(labels, contexts, strict=True):
        for name, prior in ctx.priors.items():
            if name in ctx.held:
                continue
            count[name] = count.get(name, 0) + 1
            if name in priors:
                _same_prior(name, (owner[name], priors[name]), (label, prior))
            else:
                priors[name], owner[name] = prior, label
    if max(count.values(), default=0) < 2:
        raise ConfigError(
            f"the studies {', '.join(labels)} share no calibrated parameter: calibrated "
            "together they would give their own posteriors again",
            hint="name the same physical parameter alike in each study",
        )
    return priors


def _record(res: Results) -> Record:
    ctx, em = res.context, res.emulator
    assert em is not None
    held = {n: float(ctx.priors[n].to_unit(v)) for n, v in ctx.held.items()}
    target = build_target(
        em.emulator,
        em.assembled.w_star,
        em.assembled.lam_star_prior,
        list(ctx.priors.values()),
        algebra=ctx.study.emulator.algebra,
        observations=em.assembled.observations,
    )
    return Record(label_of(ctx), target, tuple(ctx.priors), held)


def label_of(ctx: Context) -> str:
    """A study's label in the joint posterior: its name (its error parameters' prefix in
    posterior.nc, where '/' is refused)."""
    return ctx.study.study.name.replace("/", "-")


def _rows(post: Posterior, source: str) -> list[dict[str, object]]:
    flat = post.draws.reshape(-1, len(post.names))
    columns = [(name, post.priors[name].unit, flat[:, k]) for k, name in enumerate(post.names)]
    columns += [(name, d.unit, d.draws.reshape(-1)) for name, d in post.derived.items()]
    rows = []
    for name, unit, column in columns:
        if np.ptp(column) == 0.0:  # held at one value: not calibrated there
            continue
        low, high = np.quantile(column, [0.025, 0.975])
        rows.append(
            {
                "parameter": name,
                "source": source,
                "unit": unit,
                "mean": float(column.mean()),
                "sd": float(column.std(ddof=1)),
                "lower": float(low),
                "upper": float(high),
            }
        )
    return rows


def _disagreements(summary: pd.DataFrame) -> list[str]:
    """A parameter whose joint mean lies outside one record's own 95 % interval."""
    out = []
    joint_mean = dict(
        zip(
            summary.loc[summary["source"] == JOINT, "parameter"],
            summary.loc[summary["source"] == JOINT, "mean"],
            strict=True,
        )
    )
    for _, row in summary[summary["source"] != JOINT].iterrows():
        name, low, high = str(row["parameter"]), float(row["lower"]), float(row["upper"])
        if name not in joint_mean:
            continue
        mean = float(joint_mean[name])
        if not low <= mean <= high:
            out.append(
                f"{name}: the joint mean {mean:.4g} lies outside the 95 % interval "
                f"of {row['source']} alone [{low:.4g}, {high:.4g}]: the records "
                "disagree (a model error in one of them at least), and the joint posterior "
                "is a compromise neither supports; treat it as a fitting constant"
            )
    return out


@dataclass(frozen=True)
class _Settings:
    """The joint chains' settings, from the studies' ``[calibration]`` sections."""

    chains: int
    burn: int
    samples: int
    most: int
    moves: Moves
    seed: int

    @classmethod
    def of(cls, found: Sequence[tuple[Study, Results]], seed: int | None) -> _Settings:
        sections = [study.calibration for study, _ in found]
        first = found[0][1].context.seed("calibrate", sections[0].seed)
        return cls(
            chains=max(s.chains for s in sections),
            burn=max(s.burn for s in sections),
            samples=max(s.samples for s in sections),
            most=max(s.most_samples for s in sections),
            moves="joint" if any(s.moves == "joint" for s in sections) else "gibbs",
            seed=first if seed is None else int(seed),
        )


def _key(found: Sequence[tuple[Study, Results]], settings: _Settings) -> str:
    """What fixes the chains: each study's emulator file and the settings."""
    digest = hashlib.sha256(repr(settings).encode())
    for study, res in found:
        digest.update(study.study.name.encode())
        digest.update((res.context.out / emulator_store.FILE).read_bytes())
    return digest.hexdigest()[:12]


def joint(
    paths: Sequence[Path],
    out: Path,
    *,
    options: Options | None = None,
    seed: int | None = None,
    say: Callable[[str], None] = lambda _: None,
) -> JointResult:
    """Calibrate the records of ``paths`` (finished studies) together into ``out``.

    The chains take the largest ``[calibration]`` chains, burn, samples and
    maximum of the studies, ``moves = "joint"`` if any study has it, and the
    first study's calibration seed unless ``seed`` is given; they are
    extended while a diagnostic fails, and a killed run resumes from their
    snapshots in ``out``.
    """
    opts = options or Options()
    if len(paths) < 2:
        raise ConfigError(
            f"a joint calibration needs two studies or more, got {len(paths)}",
            hint="bayescal joint STUDY STUDY [STUDY ...] --out DIR",
        )
    contexts = [_prepared(Path(p)) for p in paths]
    priors = joint_priors(contexts)
    for ctx in contexts:
        if out.resolve() == ctx.out.resolve():
            raise ConfigError(
                f"--out {out} is the output folder of {ctx.study.path}: the joint posterior "
                "would replace that study's own",
                hint="give the joint calibration a folder of its own",
            )
    found = [(ctx.study, _finished(ctx)) for ctx in contexts]
    records = [_record(res) for _, res in found]
    target = JointPosterior(records, priors)
    chosen = _Settings.of(found, seed)
    say(
        f"joint calibration of {', '.join(r.label for r in records)}: {target.t} parameters "
        f"({', '.join(target.names)}), {target.d - target.t} error parameters; "
        f"{chosen.chains} chains x ({chosen.burn} + {chosen.samples}), moves {chosen.moves!r}"
    )
    notes: list[str] = []
    for ctx, rec in zip(contexts, records, strict=True):
        if ctx.study.discrepancy.enabled:
            notes.append(
                f"{rec.label}'s difference-process phase ([discrepancy] enabled) is not part "
                "of the joint calibration, which uses its calibrate stage's likelihood"
            )
        others = {n for r in records if r is not rec for n in r.calibrated}
        if not others & set(rec.calibrated):
            notes.append(
                f"{rec.label} shares no parameter with the others: its posterior is its own"
            )
        if rec.held:
            notes.append(f"{rec.label} holds {', '.join(rec.held)} at its values (not calibrated)")
    for note in notes:
        say(f"note: {note}")
    with writing(out):
        out.mkdir(parents=True, exist_ok=True)
    chains_dir = out / f"chains-{_key(found, chosen)}"
    bar = _Bar(opts, chosen.chains, chosen.burn)
    start = time.perf_counter()
    try:
        with writing(out):  # the chains' snapshots too
            post = calibrate_joint(
                target,
                n_chains=chosen.chains,
                n_burn=chosen.burn,
                n_draws=chosen.samples,
                max_draws=chosen.most,
                seed=chosen.seed,
                moves=chosen.moves,
                backend="serial" if opts.chains_backend == "serial" else "processes",
                callback=bar.open("joint calibration", chosen.samples),
                checkpoint_dir=chains_dir,
                checkpoint_seconds=opts.checkpoint_seconds,
                on_extend=lambda _, longer: bar.open(
                    f"joint calibration, extended to {longer} draws", longer
                ),
            )
    finally:
        bar.close()
    seconds = time.perf_counter() - start
    post = post.with_derived(_derived(contexts[0], post))
    alone = {rec.label: _need(res.posterior) for rec, (_, res) in zip(records, found, strict=True)}
    rows = [row for label, own in alone.items() for row in _rows(own, label)]
    summary = pd.DataFrame(rows + _rows(post, JOINT))
    warnings = [*_disagreements(summary), *bound_warnings(post.unit_draws, post.priors)]
    warnings += list(post.warnings)
    with writing(out):
        files = (
            posterior_store.save_posterior(post, out / posterior_store.FILE),
            atomic_write_text(out / SUMMARY_FILE, summary.to_csv(index=False)),
            plot_joint(out / FIGURE_FILE, post, alone),
            atomic_write_text(
                out / MARKDOWN_FILE,
                joint_markdown(summary, list(alone), warnings, FIGURE_FILE, notes),
            ),
        )
    return JointResult(
        post, summary, tuple(alone), files, tuple(warnings), tuple(notes), seconds=seconds
    )


def _derived(ctx: Context, post: Posterior) -> dict[str, Derived]:
    """The first study's derived quantities (its simulator's, its ``[derived]``) at the
    joint draws of the parameters it calibrates, its held inputs at their values."""
    names = tuple(n for n in post.names if n in ctx.priors and n not in ctx.held)
    draws = post.draws[..., [post.names.index(n) for n in names]]
    held = tuple(ctx.held)  # the study's held inputs at their values, as its own posterior has them
    fixed = np.broadcast_to([ctx.held[n] for n in held], (*draws.shape[:2], len(held)))
    return derived_at(ctx, names + held, np.concatenate([draws, fixed], axis=-1))


class _Bar:
    """The progress bar of the chains (``Options.mcmc_progress``), one per extension."""

    def __init__(self, opts: Options, n_chains: int, burn: int) -> None:
        self.factory, self.n_chains, self.burn = opts.mcmc_progress, n_chains, burn
        self.close: Callable[[], None] = lambda: None

    def open(self, what: str, kept: int) -> Callable[[int], None] | None:
        self.close()
        if self.factory is None:
            return None
        tick, self.close = self.factory(what, self.n_chains * (self.burn + kept))
        return tick


def _need(post: Posterior | None) -> Posterior:
    assert post is not None  # _finished checked it
    return post
