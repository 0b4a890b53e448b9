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
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayescal.emulator.noise import DELTA_RANGE
from bayescal.runner import forcing_fingerprint, simulator_fingerprint

if TYPE_CHECKING:
    from bayescal.config import Study
    from bayescal.pipeline.stages import Context

__all__ = ["derived_seed", "digest", "stage_keys"]


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


def stage_keys(ctx: Context) -> dict[str, str]:
    """The key of every stage for the study as it is now."""
    s = ctx.study
    dump = s.model_dump(mode="json")
    keys: dict[str, str] = {}
    keys["design"] = digest("design", dump["parameters"], dump["design"], s.study.seed)
    keys["simulate"] = digest(
        "simulate",
        keys["design"],
        simulator_fingerprint(ctx.simulator),
        forcing_fingerprint(ctx.measured.forcing),
        dump["runner"]["retries"],
        dump["runner"]["timeout"],
    )
    keys["emulator"] = digest(
        "emulator",
        keys["simulate"],
        _measured_key(ctx),
        s.outputs.calibration_dump(),
        dump["emulator"],
    )
    calibration = dict(dump["calibration"])
    if calibration.get("moves") == "gibbs":  # the default: the keys it had before the setting
        del calibration["moves"]
    elif calibration.get("moves") == "joint":  # screened joint moves draw other chains
        calibration["moves"] = "joint, screened"
    keys["calibrate"] = digest(
        "calibrate",
        keys["emulator"],
        calibration,
        *([dump["derived"]] if s.derived else []),
        # the discrepancy's variance prior reaches down to 1e-8 (it stopped at 1e-4)
        *([f"discrepancy from {DELTA_RANGE[0]:g}"] if _likelihood_discrepancy(s) else []),
    )
    keys["discrepancy"] = digest("discrepancy", keys["calibrate"], dump["discrepancy"])
    keys["predict"] = digest(
        "predict",
        keys["discrepancy"],
        dump["predict"],
        {n: p.nominal for n, p in s.parameters.items()},
        *([_held_out_key(ctx)] if s.outputs.held_out else []),
        # an in-likelihood discrepancy is conditioned on the training residuals (it added
        # its prior variance before): the predictions of such a study are computed anew
        *(["discrepancy conditioned"] if _likelihood_discrepancy(s) else []),
        # the emulator route conditions on the test window's runs and no longer adds
        # 1/lambda to the noise: its predictions are computed anew
        *(["emulator on the test window's runs"] if s.predict.method == "emulator" else []),
    )
    keys["report"] = digest("report", keys["predict"], s.study.name, s.study.description)
    return keys
