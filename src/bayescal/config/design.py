"""The ``[design]`` section: the simulator runs the emulator is trained on.

One-shot (the default): a Latin hypercube of ``runs`` runs over the priors'
bounds. Sequential (``sequential = true``): that hypercube is the first design,
then batches of runs are placed at draws of the current posterior where the
emulator is least sure, until the emulator's error measured on a new batch is
small against the measurement noise, or ``max_runs`` or ``max_minutes`` is
reached (:mod:`bayescal.pipeline.seqdesign`, docs/method.md section
"Sequential design").

``reuse_screening = true`` puts the runs of a Sobol screening first in the
design (:mod:`bayescal.pipeline.reuse`), one-shot or sequential (then the
first design, and ``max_runs`` counts them).
"""

from __future__ import annotations

from typing import Any, Literal

from bayescal.config.base import Section, field_doc

__all__ = ["DesignSection"]

#: The sequential keys, left out of the design stage's key while ``sequential`` is
#: off (so that a one-shot study keeps the key it always had).
SEQUENTIAL_KEYS = ("sequential", "batch", "max_runs", "tolerance", "max_minutes")


class DesignSection(Section):
    """``[design]``: the Latin hypercube of simulator runs, one-shot or sequential."""

    runs: int = field_doc(
        "Number of runs R of the Latin hypercube (at least parameters + 2); with "
        "sequential = true, the size of the first design. With reuse_screening, the new runs "
        "after the screening's (at least 1, and the screening's runs count towards "
        "parameters + 2); with both, 0 makes the screening's runs alone the first design.",
        30,
        default=30,
        ge=0,
    )
    seed: int | None = field_doc(
        "Seed; derived from [study].seed if omitted.", 1, default=None, ge=0
    )
    optimization: Literal["none", "random-cd", "lloyd"] = field_doc(
        "Space-filling optimisation of scipy.stats.qmc.LatinHypercube.", "none", default="random-cd"
    )
    sequential: bool = field_doc(
        "Grow the design in batches placed where the current posterior puts its mass and "
        "the emulator is least sure, instead of spreading every run over the prior box "
        "(docs/method.md, 'Sequential design'). Each batch refits the emulator and a short "
        "calibration; the runs are cached, and a killed design resumes after its last "
        "finished batch. With reuse_screening, the first design is the screening's runs then "
        "`runs` new ones, and the batches hold the screened-out candidates at their nominal "
        "values, as the posterior does.",
        True,
        default=False,
    )
    batch: int | None = field_doc(
        "sequential: runs per batch (default: twice the number of calibrated parameters, "
        "at least 4). A batch runs in parallel on the [runner] backend.",
        8,
        default=None,
        ge=1,
    )
    max_runs: int | None = field_doc(
        "sequential: at most this many runs in all, the first design included (default: "
        "three times runs). With reuse_screening the screening's runs count too (they are "
        "not run again; the default is then the screening's runs + three times runs, so set "
        "it with runs = 0).",
        90,
        default=None,
        ge=2,
    )
    tolerance: float = field_doc(
        "sequential: the design stops when the emulator's error measured on the newest "
        "batch (run at posterior draws, predicted before the batch joined the emulator's "
        "runs) would move the posterior mean by at most this many posterior standard "
        "deviations (the posterior mean's shift in the current posterior's own SDs, "
        "docs/method.md 'Sequential design') and the last two short "
        "calibrations' SDs agree within 20 %; it also stops after "
        "three batches without a smaller shift "
        "(the emulator's error floor). [-]",
        0.2,
        default=0.2,
        gt=0,
    )
    max_minutes: float | None = field_doc(
        "sequential: start no new batch after this many minutes of design (the runs "
        "already made are kept). [min]",
        20,
        default=None,
        gt=0,
    )
    reuse_screening: bool = field_doc(
        "Train the emulator on the runs of the Sobol screening too ([screening] method = "
        "'sobol', run by `bayescal screen` into the same output folder): the design is the "
        "screening's Latin hypercube followed by `runs` new runs, which vary the calibrated "
        "parameters and hold the screened-out candidates at their nominal values. The "
        "emulator's parameter inputs are then every parameter the screening varied, and the "
        "calibration and predictions hold the screened-out ones at their nominal values "
        "(they are not calibrated); the screening runs come from the run cache, not the "
        "simulator. With sequential = true, the screening's runs and `runs` new ones are the "
        "first design, the batches hold the screened-out candidates at nominal too, and "
        "max_runs counts the screening's runs. Not with a Morris screening, sampler 'nuts', "
        "[discrepancy] enabled or [study] prior_from. Off by default: it changes the "
        "emulator's inputs (more of them, a longer training) and needs the screening's "
        "results in the output folder.",
        True,
        default=False,
    )

    def key_dump(self) -> dict[str, Any]:
        """The section as the design stage's key sees it (without the sequential keys
        while sequential is off)."""
        dump = self.model_dump(mode="json")
        if not self.sequential:
            for name in SEQUENTIAL_KEYS:
                dump.pop(name, None)
        if not self.reuse_screening:  # a study without it keeps the key it always had
            dump.pop("reuse_screening", None)
        return dump

    def batch_size(self, parameters: int) -> int:
        """Runs per batch for ``parameters`` calibrated parameters."""
        return self.batch if self.batch is not None else max(4, 2 * parameters)

    def run_cap(self, reused: int = 0) -> int:
        """The most runs of a sequential design, the first design included.

        ``reused``: the screening's runs at the head of the design (``reuse_screening``),
        which count against ``max_runs`` and its default (``reused + 3 * runs``).
        """
        return self.max_runs if self.max_runs is not None else reused + 3 * self.runs
