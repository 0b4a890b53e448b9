"""The noise of the simulator route's bands, estimated again from the re-run simulator.

With ``[predict] method = "simulator"`` the model part of a band is the
simulator re-run at posterior draws, which does not make the emulator's error
that the calibration's ``lambda*`` also holds: :func:`simulator_noise` estimates
each output's noise again at every draw from the run's residuals on the
training periods (method.md section 6, "The noise of the simulator route").
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

import numpy as np

from bayescal.calibration.conditional import OutputDiscrepancy
from bayescal.calibration.posterior import Posterior
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator

__all__ = ["NoiseChoice", "simulator_noise"]

#: ``[predict] noise``: where the simulator route's noise comes from.
NoiseChoice = Literal["simulator", "basis", "calibration"]


def simulator_noise(
    assembled: Assembled,
    runs: Mapping[str, np.ndarray],
    posterior: Posterior,
    pick: np.ndarray,
    noise: NoiseChoice = "simulator",
    emulator: Emulator | None = None,
) -> np.ndarray:
    """The observation noise of the re-run simulator's bands, as precisions ``(S, O)``.

    The calibration's ``lambda*`` is the precision of what separates the
    measurement from the *emulator* in the output basis: the sensor's noise, the
    model's misfit and the emulator's own error. The simulator re-run at a draw
    does not make the emulator's error, so with ``[predict] method = "simulator"``
    every output's noise is estimated again at every draw ``s`` from the
    residuals of the run on the training periods (training data only):
    ``Gamma(a + N/2, b + Q/2)`` (:meth:`ObservationModel.precision_given`; ``a,
    b`` the output's noise prior, ``N`` its training samples, ``Q`` the
    residuals' sum of squares), and the band uses the posterior mean of the
    noise variance, ``(b + Q/2) / (a + N/2 - 1)``, returned as its reciprocal.
    A band is the distribution of one sample, so what it needs is the noise's
    *marginal* variance (``1/lambda*`` for AR(1) errors too: ``R`` has a unit
    diagonal), which the plain mean square estimates without bias whatever the
    residuals' correlation. Whitening with the calibration's ``phi`` would not:
    that ``phi`` describes the emulator's residuals, and whitening residuals
    less correlated than it inflates them (by ``(1 + phi^2) / (1 - phi^2)``
    for white ones).

    An output with an in-likelihood discrepancy holds it on its basis weights.
    Given the ``emulator`` (its discrepancy's covariance over the conditions),
    its noise is the conditional of ``lambda*`` given the run at the draw and
    the draw's ``phi`` and ``r`` (:meth:`OutputDiscrepancy.noise_given`: the
    residuals' weights under the discrepancy's covariance plus the noise block,
    and the part of the residuals the basis leaves), as the calibration has it
    without the emulator's variance. With ``noise = "basis"`` it is estimated
    from that last part alone (:meth:`ObservationModel.precision_out_of_basis`:
    ``m (n_o - p_o)`` degrees of freedom, prewhitened with the draw's ``phi``),
    which leaves out the in-basis misfit the discrepancy's GP does not explain.
    Without the emulator it keeps the calibration's ``lambda*``, as every output
    does with ``noise = "calibration"``. The caller krigs the discrepancy with
    the noise returned (:func:`bayescal.pipeline.predict.conditioned_discrepancy`);
    docs/validation/case-studies-log.md measures the choices.

    Parameters
    ----------
    assembled
        The assembled data (its measured training periods and standardisation).
    runs
        Output name -> the simulator at the draws ``(S, n_total)``.
    posterior
        The calibration posterior (``lambda*`` of the draws).
    pick
        Indices of the draws in the flattened draws ``(S,)``.
    noise
        ``[predict] noise``: ``"simulator"`` (above), ``"basis"`` (an output
        with a discrepancy gets the noise its basis leaves) or ``"calibration"``
        (every output keeps the draws' ``lambda*``).
    emulator
        The trained emulator: with ``noise = "simulator"`` an output with a
        discrepancy gets the conditional noise (without it, ``lambda*``).
    """
    obs = assembled.observations
    lam = np.array(posterior.lam_stars.reshape(-1, obs.n_outputs)[pick], dtype=float)
    if noise == "calibration":
        return lam
    outside_basis = noise == "basis"
    aux = np.asarray(posterior.aux, dtype=float).reshape(-1, len(posterior.aux_names))[pick]
    unit = posterior.unit_draws.reshape(-1, len(posterior.names))[pick]
    for q, out in enumerate(obs.outputs):
        conditional = bool(out.discrepancy) and not outside_basis and emulator is not None
        if out.name not in runs or (out.discrepancy and not (outside_basis or conditional)):
            continue
        field = None
        if conditional:
            assert emulator is not None
            no_periods = np.zeros((0, assembled.x.shape[1]))
            field = OutputDiscrepancy.build(emulator, obs, q, no_periods)
        st = assembled.outputs.standardisations[q]
        measured = obs.block(q)[1]
        sims = assembled.layout.cut(np.asarray(runs[out.name], dtype=float))
        phi_at = (
            posterior.aux_names.index(obs.coordinate("phi", q)) if q in obs.ar_outputs else None
        )
        for s in range(pick.size):
            y_sim = (sims[s] - st.mean[:, None]) / st.sd[:, None]
            resid = measured - y_sim
            if not out.discrepancy:
                shape, rate = obs.precision_given(q, resid)
                lam[s, q] = (shape - 1.0) / rate
                continue
            phi = 0.0 if phi_at is None else float(aux[s, phi_at])
            shape, rate = obs.precision_out_of_basis(q, resid, phi)
            if field is None:
                lam[s, q] = (shape - 1.0) / rate
                continue
            values = dict(zip(posterior.aux_names, aux[s], strict=True))
            model = obs.weights_of(q, y_sim, phi)
            lam[s, q] = field.noise_given(values, model, (shape, rate), unit[s])
    return lam
