"""How large the model error the data show is: the in-likelihood discrepancy against the noise.

An output with ``[outputs.errors.NAME] discrepancy`` has, in the likelihood, a
discrepancy of basis weights ``delta_j ~ N(0, r tau_j^-1)`` per period (over the
periods' conditions, ``delta_rel``, and/or of each period's own,
``delta_ind``): what the model at theta* misses of the measured response. At
a posterior draw its variance at sample ``t`` of a period, in the output's
unit, is

    s_t^2 sum_j r tau_j^-1 K_tj^2,

``K`` the output's basis vectors and ``s_t`` its standardisation scale; the
root of its mean over the period's samples is the discrepancy's SD
(:func:`discrepancy_sd`). Divided by the draw's noise SD ``s / sqrt(lambda*)``
it says how large the model's error is against the measurement noise
(:func:`discrepancy_ratios`).

With a correct model the data leave ``r`` free down to its lower bound, and the
lower end of the ratio's interval lies far below one tenth of the noise SD; on
the virtual wall with a 15 mm plaster layer the model lacks, the whole interval
lies at 2-9 noise SDs (docs/validation/case-studies-log.md#model-error-size).
Where the 2.5 % quantile of the ratio exceeds :data:`MODEL_ERROR_FLOOR` the data
show a model error for certain: ``show``, ``run`` and the report say so on their
first screen (:func:`bayescal.report.trust.trust_warnings`), since the physics
behind it is in no parameter, and quantities derived from the parameters (a
U-value, a heat capacity) describe the model, not the building.

The SD itself is not shown as the size of the model's error: it is the scale of
the Gaussian process, and on the plastered wall its 95 % interval (0.8-3.0 W/m²)
lay 2-7 times above the RMS of the true model error on the training days (0.42
W/m², the true wall's noise-free flux minus the model's at the true parameters).
Only the verdict is said (:meth:`ModelErrorSize.line`), whose false-alarm and
detection rates were measured on known truths.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bayescal.calibration.posterior import Posterior
from bayescal.emulator.gp import Emulator

__all__ = ["MODEL_ERROR_FLOOR", "ModelErrorSize", "discrepancy_ratios", "discrepancy_sd"]

FloatArray = NDArray[np.float64]
#: The discrepancy's SD, in noise SDs, that the 2.5 % quantile of its posterior must
#: exceed for the first screen to say the model misses part of the measurements. [-]
MODEL_ERROR_FLOOR = 0.25


def discrepancy_sd(emulator: Emulator, posterior: Posterior) -> dict[str, FloatArray]:
    """Output name -> draws ``(chains, draws)`` of its in-likelihood discrepancy's SD in
    the output's unit (outputs without one are absent)."""
    k = emulator.basis.k
    sd = np.asarray(emulator.outputs.sd, dtype=float)
    variances = np.array([kern.variance for kern in emulator.kernels])
    names = list(posterior.aux_names)
    single = len(posterior.noise) == 1
    out: dict[str, FloatArray] = {}
    for o in posterior.noise:
        if not o.delta_parts:
            continue
        rows, bases = slice(*o.rows), list(o.bases)
        # mean over the period's samples of s_t^2 K_tj^2, per basis vector
        spread = np.mean((k[rows][:, bases] * sd[rows, None]) ** 2, axis=0)
        scale = float(spread @ variances[bases])
        r = np.zeros(posterior.aux.shape[:2])
        for kind in o.delta_parts:
            r = r + posterior.aux[..., names.index(kind if single else f"{kind}_{o.name}")]
        out[o.name] = np.sqrt(r * scale)
    return out


class ModelErrorSize:
    """One output's discrepancy SD and its ratio to the noise SD, draw by draw.

    Attributes
    ----------
    output, unit
        The output and its unit.
    sd
        The discrepancy's SD per draw (flattened). [unit]
    ratio
        That SD divided by the draw's noise SD. [-]
    """

    def __init__(self, output: str, unit: str, sd: FloatArray, ratio: FloatArray) -> None:
        self.output, self.unit = output, unit
        self.sd, self.ratio = sd.reshape(-1), ratio.reshape(-1)

    @property
    def shown(self) -> bool:
        """Whether the data show a model error for certain: the ratio's 2.5 % quantile
        exceeds :data:`MODEL_ERROR_FLOOR`."""
        return float(np.quantile(self.ratio, 0.025)) > MODEL_ERROR_FLOOR

    def line(self) -> str:
        """The verdict in words, without a size: the discrepancy's SD is the scale of a
        Gaussian process, not the size of the model's error (on the plastered virtual
        wall its 95 % interval lay 2-7 times above the RMS of the true model error), so
        only the rule's verdict is said, whose error rates were measured on known truths."""
        if self.shown:
            return (
                f"{self.output}: the data show a model error (the in-likelihood "
                f"discrepancy's scale stays above {MODEL_ERROR_FLOOR:g} noise SDs in 97.5 % "
                "of the posterior, where a correct model leaves it near zero)"
            )
        return f"{self.output}: no model error shown by the in-likelihood discrepancy"


def discrepancy_ratios(emulator: Emulator, posterior: Posterior) -> tuple[ModelErrorSize, ...]:
    """Every output with an in-likelihood discrepancy: its SD against the noise SD."""
    noise = posterior.noise_sd()
    units = {o.name: o.unit for o in posterior.noise}
    return tuple(
        ModelErrorSize(name, units[name], sd, sd / noise[name])
        for name, sd in discrepancy_sd(emulator, posterior).items()
        if name in noise
    )
