"""The ``[predict]`` section: calibrated predictions and their bands.

The routes (simulator re-run at posterior draws, the emulator, or ``auto``:
the emulator where it is measured good enough at held-out runs,
:mod:`bayescal.pipeline.route`) are computed by :mod:`bayescal.pipeline.stages`
and :mod:`bayescal.pipeline.predict`.
"""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from bayescal.config.base import Section, field_doc

__all__ = ["PredictSection"]


class PredictSection(Section):
    """``[predict]``: calibrated predictions on the training and test windows."""

    draws: int = field_doc(
        "Posterior draws (thinned evenly over all chains) propagated through the emulator.",
        300,
        default=300,
        ge=20,
    )
    level: float = field_doc(
        "Probability of the prediction band. [-]", 0.95, default=0.95, gt=0, lt=1
    )
    method: Literal["emulator", "simulator", "auto"] = field_doc(
        "'auto': run the simulator at `check_runs` of the `runs` posterior draws, held out "
        "from the emulator, and take the emulator route when its error there (its mean "
        "against the runs' part on the output basis, on the test window) is at most "
        "`check_tolerance` noise SDs for every output, else the "
        "simulator route (its runs then include those). "
        "Calibrated predictions from the simulator re-run at `runs` posterior draws (the "
        "default: exact physics, bands that hold their rate on test periods whose "
        "conditions the training periods did not span; costs `runs` runs), or from the "
        "emulator at `draws` posterior draws (no runs, for a simulator too slow to re-run; "
        "on the test window the emulator is conditioned on the design runs there too and "
        "its band adds the part of those runs outside the output basis beyond the training "
        "periods' share: over the validation's known truths its 95 % band covered "
        "0.945-0.957 of the test samples, the simulator route's 0.950-0.969). With a "
        "discrepancy, the corrected prediction adds "
        "Delta to the same kind of prediction (for 'simulator': runs at draws of the "
        "Delta phase's theta*).",
        "emulator",
        default="simulator",
    )
    runs: int = field_doc(
        "Posterior draws at which the simulator is re-run (method = 'simulator').",
        50,
        default=50,
        ge=10,
    )
    check_runs: int = field_doc(
        "method = 'auto': simulator runs at posterior draws that measure the emulator's "
        "error before the route is chosen.",
        8,
        default=5,
        ge=1,
    )
    check_tolerance: float = field_doc(
        "method = 'auto': the emulator route is taken when its RMS error at the held-out "
        "runs is at most this many noise SDs for every calibrated output (0.3: a 95 % band "
        "of the noise alone would still cover about 94 %). [-]",
        0.2,
        default=0.3,
        gt=0,
    )
    noise: Literal["simulator", "basis", "calibration"] = field_doc(
        "Observation noise in the bands of method = 'simulator' (and of 'auto''s emulator "
        "route with its centre completed, off_basis = 'check_runs'): 'simulator' (the default) "
        "estimates each output's noise again at every draw from the re-run simulator's "
        "residuals on the training periods (its posterior mean given them; the "
        "calibration's lambda* also holds the emulator's own error, which a re-run "
        "simulator does not make, and its bands over-covered where the emulator was the "
        "weak link); for an output with an in-likelihood discrepancy, its conditional "
        "given the run and the draw's discrepancy variance (the calibration's conditional "
        "of lambda* without the emulator's variance), its discrepancy kriged with that "
        "noise. 'basis': the same, but such an output's noise from the part of the "
        "residuals its basis leaves alone (the discrepancy lies on the basis): it leaves "
        "out the in-basis misfit the discrepancy's GP does not explain (too narrow on the "
        "free-float box's test windows: the case-studies log). 'calibration' uses the "
        "draw's lambda*. The corrected prediction (the difference process) always uses "
        "lambda*.",
        "calibration",
        default="simulator",
    )
    off_basis: Literal["check_runs", "none"] = field_doc(
        "method = 'auto', where it takes the emulator route: 'check_runs' (the default) "
        "completes the emulator's centre with the held-out runs' mean part off the output "
        "basis (the emulator predicts the basis weights only; on the office example that "
        "part moved the hourly gas CV(RMSE) from about 6 % to 18 %), adds the part's "
        "spread over those runs to the band, and estimates the noise again from the "
        "completed centre's residuals on the training periods, as the simulator route "
        "does (needs check_runs >= 2). 'none': the centre on the basis, the part off it in "
        "the band's noise (lambda*) and, on the test window, the design runs' excess of it "
        "over the training periods' only. The corrected prediction (the difference process) "
        "is not completed: Delta, estimated against the centre on the basis, holds that part.",
        "none",
        default="check_runs",
    )

    @model_validator(mode="after")
    def _completion_needs_two_runs(self) -> PredictSection:
        if self.method == "auto" and self.off_basis == "check_runs" and self.check_runs < 2:
            raise ValueError(
                f"off_basis = 'check_runs' completes the emulator route's centre with the "
                f"held-out runs' mean part off the basis and needs at least two of them "
                f"(check_runs = {self.check_runs}): raise check_runs, or set off_basis = 'none'"
            )
        return self
