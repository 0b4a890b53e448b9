"""Stage keys and seeds: what a stage's result depends on, as a hash.

Every stage has a *key*: the SHA-256 of everything its result depends on (the
settings it reads and the keys of the stages before it). The runner
(:mod:`bayescal.pipeline.run`) reuses a stage whose recorded key
(:class:`bayescal.store.stages.StageLog`) equals the key it computes now.
The keys cover settings and inputs, not bayescal's own code. An output folder
written by an earlier bayescal is reused as long as these functions give the
same keys (``tests/pipeline/test_stage_keys.py`` pins them for the wall example).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from bayescal.emulator.noise import DELTA_RANGE
from bayescal.runner import forcing_fingerprint, simulator_fingerprint

if TYPE_CHECKING:
    from bayescal.config import Study
    from bayescal.data.measured import MeasuredData
    from bayescal.design import Prior
    from bayescal.simulators.base import Simulator


class Context(Protocol):
    """What the keys read of a loaded study (:class:`bayescal.pipeline.stages.Context`)."""

    @property
    def study(self) -> Study: ...

    @property
    def simulator(self) -> Simulator: ...

    @property
    def measured(self) -> MeasuredData: ...

    @property
    def priors(self) -> Mapping[str, Prior]: ...


__all__ = ["derived_seed", "digest", "keys_and_inputs", "stage_inputs", "stage_keys"]


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in sorted(obj.items(), key=lambda kv: str(kv[0]))}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return hashlib.sha256(np.ascontiguousarray(obj).tobytes()).hexdigest() + str(obj.shape)
    if isinstance(obj, float | int | str | bool) or obj is None:
        return obj
    if isinstance(obj, Path):
        return str(obj)
    return repr(obj)


def digest(*parts: Any) -> str:
    """SHA-256 (hex) of the canonical JSON of ``parts`` (arrays by content)."""
    text = json.dumps(_plain(list(parts)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def derived_seed(master: int, stage: str) -> int:
    """A seed for ``stage`` derived from the study's master seed."""
    entropy = [int(master), *stage.encode()]
    return int(np.random.SeedSequence(entropy).generate_state(1)[0])


def _measured_key(ctx: Context) -> str:
    m = ctx.measured
    layout = dataclasses.asdict(m.layout)
    return digest(forcing_fingerprint(m.forcing), dict(m.outputs), layout, m.times)


def _held_out_key(ctx: Context) -> str:
    """The held-out sensors: names, stated accuracies and measured series."""
    outputs = ctx.study.outputs
    errors = {n: outputs.errors[n].model_dump(mode="json") for n in outputs.held_out}
    return digest(list(outputs.held_out), errors, dict(ctx.measured.held_out))


def _likelihood_discrepancy(study: Study) -> bool:
    """Whether a calibrated output carries a discrepancy in the likelihood."""
    errors = study.outputs.errors
    return any(errors[n].discrepancy for n in study.outputs.calibrate if n in errors)


#: One input of a stage key: its name, its value, and whether a table's entries are
#: named one by one in :func:`stage_inputs` (``parameters.cp_fb``, ``design.runs``).
Item = tuple[str, Any, bool]


def _predict_dump(predict: dict[str, Any]) -> dict[str, Any]:
    """``[predict]`` as the predict key sees it: the check of ``method = "auto"`` only
    where it is used, and its ``off_basis`` only where it completes the emulator's
    centre (a study without them keeps the key it always had: ``off_basis = "none"``
    makes the predictions of before the option)."""
    unused = {"off_basis"} if predict.get("off_basis", "none") == "none" else set()
    if predict.get("method") != "auto":
        unused |= {"check_runs", "check_tolerance", "off_basis"}
    return {k: v for k, v in predict.items() if k not in unused}


def _keyed(stage: str, items: list[Item]) -> tuple[str, dict[str, str]]:
    """The key of ``stage`` (the digest of the items' values in order, exactly as the
    keys were always computed) and a short digest of each named input."""
    key = digest(stage, *(value for _, value, _ in items))
    inputs: dict[str, str] = {}
    for name, value, by_entry in items:
        if by_entry and isinstance(value, dict):
            inputs |= {f"{name}.{k}": digest(v)[:16] for k, v in value.items()}
            inputs.setdefault(name, digest(sorted(value))[:16])  # entries added or removed
        else:
            inputs[name] = digest(value)[:16]
    return key, inputs


def stage_keys(ctx: Context) -> dict[str, str]:
    """The key of every stage for the study as it is now."""
    return keys_and_inputs(ctx)[0]


def stage_inputs(ctx: Context) -> dict[str, dict[str, str]]:
    """Every stage's inputs, each by name with a short digest of its value: what
    ``stages.json`` records beside the key, so that a stage run again can say which
    input changed (``parameters.cp_fb``, ``emulator.pca_variance``, ``the design stage``)."""
    return keys_and_inputs(ctx)[1]


def keys_and_inputs(ctx: Context) -> tuple[dict[str, str], dict[str, dict[str, str]]]:
    """:func:`stage_keys` and :func:`stage_inputs` together (the inputs hashed once)."""
    s = ctx.study
    dump = s.model_dump(mode="json")
    keys: dict[str, str] = {}
    inputs: dict[str, dict[str, str]] = {}

    def stage(name: str, *items: Item) -> None:
        keys[name], inputs[name] = _keyed(name, list(items))

    design: list[Item] = [
        ("parameters", dump["parameters"], True),
        ("design", s.design.key_dump(), True),
        ("study.seed", s.study.seed, False),
    ]
    if s.design.sequential:  # the batches follow the runs, the emulator and the posterior
        design += [
            ("simulator", simulator_fingerprint(ctx.simulator), False),
            ("boundary conditions", forcing_fingerprint(ctx.measured.forcing), False),
            ("measured data and periods", _measured_key(ctx), False),
            ("outputs", s.outputs.calibration_dump(), True),
            ("emulator", dump["emulator"], True),
            ("calibration", dump["calibration"], True),
        ]
    if s.design.reuse_screening:  # the screening's hypercube is the design's first runs
        design.append(("screening", dump["screening"], True))
    if s.study.prior_from is not None:  # the previous posterior's density, not only its path
        specs = {n: p.spec() for n, p in ctx.priors.items()}
        design.append(("study.prior_from (the previous posterior)", specs, False))
    stage("design", *design)
    stage(
        "simulate",
        ("the design stage", keys["design"], False),
        ("simulator", simulator_fingerprint(ctx.simulator), False),
        ("boundary conditions", forcing_fingerprint(ctx.measured.forcing), False),
        ("runner.retries", dump["runner"]["retries"], False),
        ("runner.timeout", dump["runner"]["timeout"], False),
    )
    stage(
        "emulator",
        ("the simulate stage", keys["simulate"], False),
        ("measured data and periods", _measured_key(ctx), False),
        ("outputs", s.outputs.calibration_dump(), True),
        ("emulator", dump["emulator"], True),
    )
    calibration = dict(dump["calibration"])
    if calibration.get("moves") == "gibbs":  # the default: the keys it had before the setting
        del calibration["moves"]
    elif calibration.get("moves") == "joint":  # screened joint moves draw other chains
        calibration["moves"] = "joint, screened"
    stage(
        "calibrate",
        ("the emulator stage", keys["emulator"], False),
        ("calibration", calibration, True),
        *([("derived", dump["derived"], True)] if s.derived else []),
        # the discrepancy's variance prior reaches down to 1e-8 (it stopped at 1e-4)
        *(
            [("discrepancy prior range", f"discrepancy from {DELTA_RANGE[0]:g}", False)]
            if _likelihood_discrepancy(s)
            else []
        ),
    )
    stage(
        "discrepancy",
        ("the calibrate stage", keys["calibrate"], False),
        ("discrepancy", dump["discrepancy"], True),
    )
    stage(
        "predict",
        ("the discrepancy stage", keys["discrepancy"], False),
        ("predict", _predict_dump(dump["predict"]), True),
        ("nominal values", {n: p.nominal for n, p in s.parameters.items()}, False),
        *([("held-out sensors", _held_out_key(ctx), False)] if s.outputs.held_out else []),
        # an in-likelihood discrepancy is conditioned on the training residuals (it added
        # its prior variance before): the predictions of such a study are computed anew
        *(
            [("discrepancy conditioning", "discrepancy conditioned", False)]
            if _likelihood_discrepancy(s)
            else []
        ),
        # the simulator route's noise of an output with a discrepancy is its conditional
        # given the run (it was the calibration's lambda*): such predictions anew
        *(
            [("discrepancy noise", "conditional given the run", False)]
            if _likelihood_discrepancy(s) and s.predict.noise == "simulator"
            else []
        ),
        # the emulator route conditions on the test window's runs and no longer adds
        # 1/lambda to the noise: its predictions are computed anew
        *(
            [("emulator route", "emulator on the test window's runs", False)]
            if s.predict.method == "emulator"
            else []
        ),
    )
    stage(
        "report",
        ("the predict stage", keys["predict"], False),
        ("study.name", s.study.name, False),
        ("study.description", s.study.description, False),
    )
    return keys, inputs
