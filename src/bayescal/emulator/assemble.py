"""Assembly of simulations and measurements into the emulator's data (method.md section 2).

From ``R`` simulator runs over the whole record, the measured record and the
boundary-condition series, :func:`assemble` builds everything the emulator and
the calibration need:

* ``Y`` (``N x R m*``): every run cut into the ``m*`` training periods, columns
  **run-major** (column ``k m* + i`` is period ``i`` of run ``k``), the row
  order of :mod:`bayescal.emulator.kron`; ``Y*`` (``N x m*``) the measured
  periods. With several outputs each is standardised on its own and they are
  stacked along the within-period axis (``N = sum n_q``).
* standardisation from the simulations only (point-wise mean; point-wise or
  one-per-output scale), applied to ``Y*`` too;
* one GPMSA-scaled PCA basis per output, stacked block-diagonally into ``K``
  (``p_q`` by variance fraction or count), the weights ``W`` (eq. 6) and
  ``W*`` (eq. 13), and the Gamma prior of ``lambda`` (eq. 7);
* every output's observation error model
  (:class:`~bayescal.emulator.noise.ObservationModel`: white or AR(1) errors,
  the prior of its precision ``lambda*`` from a stated sensor accuracy or a
  weak default);
* the variable conditions ``x`` from a PCA of every boundary-condition series
  over the periods, normalised to [0, 1], and ``theta`` normalised by the prior
  bounds;
* the test-window periods transformed the same way (``x_test``, ``Y*_test``).

Layout convention for inputs: a run's or the record's series has length
``n_total`` on the study clock; :class:`bayescal.periods.PeriodLayout` says
where the periods lie.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from bayescal.design import Design, Prior
from bayescal.emulator.basis import (
    Basis,
    InputPCA,
    Normaliser,
    Scale,
    Standardisation,
    block_basis,
    input_pca,
    standardise,
)
from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.noise import (
    DEFAULT_NOISE_PRIOR,
    RELATIVE_UNIT,
    DiscrepancyKind,
    ErrorModel,
    ObservationModel,
    OutputNoise,
    noise_prior_from_sd,
)
from bayescal.errors import ConfigError, DataError
from bayescal.glossary import GLOSSARY
from bayescal.periods import PeriodLayout

__all__ = ["Assembled", "NoiseSpec", "OutputStack", "assemble", "runs_to_columns", "with_history"]


@dataclass(frozen=True)
class NoiseSpec:
    """What the study says about one output's measurement error.

    Parameters
    ----------
    model
        ``"white"`` (independent errors, the paper) or ``"ar1"`` (AR(1) within
        a period, coefficient sampled).
    sd
        The sensor's accuracy as a standard deviation, or a range ``(low,
        high)``, in the output's unit; ``None``: a weak default prior
        (:data:`~bayescal.emulator.noise.DEFAULT_NOISE_PRIOR`). [unit]
    discrepancy
        Whether to add a model discrepancy, and which: ``True`` or
        ``"conditions"`` over the periods' conditions, ``"independent"``
        between periods, ``"both"`` (:class:`~bayescal.emulator.noise.OutputNoise`).
    relative
        Whether the output's values are ``log(y + floor)``
        (:class:`~bayescal.emulator.noise.LogLevel`, applied by the caller):
        its noise SD and ``sd`` are then fractions of the level.
    """

    model: ErrorModel = "white"
    sd: float | tuple[float, float] | None = None
    discrepancy: bool | DiscrepancyKind = False
    relative: bool = False


@dataclass(frozen=True)
class OutputStack:
    """Standardisation of one or more outputs and their stacking.

    Parameters
    ----------
    names
        Output names (glossary), in stacking order.
    standardisations
        One :class:`Standardisation` per output, in the output's unit.
    """

    names: tuple[str, ...]
    standardisations: tuple[Standardisation, ...]

    @property
    def sizes(self) -> tuple[int, ...]:
        """Samples per period of each output ``n_q``."""
        return tuple(int(s.mean.size) for s in self.standardisations)

    @property
    def slices(self) -> dict[str, slice]:
        """Output name -> its rows in the stacked arrays."""
        bounds = np.concatenate([[0], np.cumsum(self.sizes)])
        return {n: slice(int(bounds[q]), int(bounds[q + 1])) for q, n in enumerate(self.names)}

    @property
    def mean(self) -> FloatArray:
        """Stacked point-wise means ``(N,)``, each block in its output's unit."""
        return np.concatenate([s.mean for s in self.standardisations])

    @property
    def sd(self) -> FloatArray:
        """Stacked point-wise standard deviations ``(N,)``, each in its output's unit."""
        return np.concatenate([s.sd for s in self.standardisations])

    def apply(self, periods: Mapping[str, ArrayLike]) -> FloatArray:
        """Standardise and stack ``{name: (n_q, m')}`` -> ``(N, m')``; NaN passes through."""
        missing = [n for n in self.names if n not in periods]
        if missing:
            raise DataError(f"output(s) {missing} missing; expected {list(self.names)}")
        blocks = []
        for name, st in zip(self.names, self.standardisations, strict=True):
            arr = np.asarray(periods[name], dtype=float)
            if arr.ndim != 2 or arr.shape[0] != st.mean.size:
                raise DataError(
                    f"output {name!r} has periods of shape {arr.shape}, expected "
                    f"({st.mean.size}, periods)"
                )
            blocks.append((arr - st.mean[:, None]) / st.sd[:, None])
        return np.vstack(blocks)

    def invert(self, y_std: ArrayLike) -> FloatArray:
        """Stacked standardised ``(N, m')`` back to the outputs' units."""
        arr = np.asarray(y_std, dtype=float)
        return arr * self.sd[:, None] + self.mean[:, None]

    def split(self, stacked: ArrayLike) -> dict[str, FloatArray]:
        """Stacked ``(N, ...)`` -> ``{name: (n_q, ...)}``."""
        arr = np.asarray(stacked)
        return {name: arr[sl] for name, sl in self.slices.items()}


@dataclass(frozen=True)
class Assembled:
    """Everything the emulator and the calibration are built from (immutable).

    Attributes
    ----------
    parameter_names
        Calibration parameters, in the design's column order.
    priors
        Parameter name -> prior (its bounds normalise ``theta``).
    theta_normaliser
        Prior bounds as a :class:`Normaliser`.
    theta
        Normalised design, ``(R, t)``, in [0, 1]. [-]
    layout
        Warm-up, periods and test window.
    outputs
        Standardisation and stacking of the outputs.
    basis
        PCA basis of the standardised simulations.
    inputs
        PCA of the boundary-condition series over the training periods.
    x
        Normalised variable conditions of the training periods, ``(m*, s)``. [-]
    y_std
        Standardised simulations, ``(N, R m*)``, run-major columns. [-]
    y_star_std
        Standardised measured periods, ``(N, m*)``. [-]
    w
        Simulator weights ``W_hat``, ``(R m*, p)``, run-major rows (eq. 6). [-]
    w_star
        Measured weights ``W*_hat``, ``(m*, p)`` (eq. 13). [-]
    lam_prior
        ``(shape, rate)`` of the Gamma prior of ``lambda`` after eq. 7.
    lam_star_prior
        ``(shape, rate)`` of the Gamma prior of the first output's ``lambda*``,
        built like eq. 7 from ``Y*`` (for callers that know one white output).
    x_test
        Variable conditions of the periods covering the test window, ``(m_test, s)``
        (outside [0, 1] for conditions not seen in training). [-]
    y_star_test_std
        Standardised measured test periods, ``(N, m_test)``; NaN where missing. [-]
    observations
        The outputs' error models with the measured training periods.
    y_test_sim_std
        The design runs on the periods covering the test window, standardised
        like ``y_std``, ``(N, R m_test)``, run-major columns: the simulator is
        driven by the known boundary conditions there, so the emulator's
        predictions on the test window are conditioned on them too
        (:meth:`~bayescal.emulator.gp.Emulator.extended`). No measurement of
        the test window enters. ``None``: no test window, or a run not finite
        there. [-]
    """

    parameter_names: tuple[str, ...]
    priors: Mapping[str, Prior]
    theta_normaliser: Normaliser
    theta: FloatArray
    layout: PeriodLayout
    outputs: OutputStack
    basis: Basis
    inputs: InputPCA
    x: FloatArray
    y_std: FloatArray
    y_star_std: FloatArray
    w: FloatArray
    w_star: FloatArray
    lam_prior: tuple[float, float]
    lam_star_prior: tuple[float, float]
    x_test: FloatArray
    y_star_test_std: FloatArray
    observations: ObservationModel
    y_test_sim_std: FloatArray | None = None

    @property
    def n_runs(self) -> int:
        """``R``."""
        return int(self.theta.shape[0])

    @property
    def n_periods(self) -> int:
        """``m*``."""
        return int(self.x.shape[0])

    @property
    def input_labels(self) -> list[str]:
        """Labels of the columns of ``z = [theta, x]``."""
        return list(self.parameter_names) + self.inputs.labels

    def out_of_basis_excess(self) -> FloatArray:
        """The out-of-basis variance of the test window beyond the training periods', ``(N,)``.

        Per output (standardised units, one value for its rows): the mean square of
        what the output basis leaves of the design runs on the periods covering the
        test window, less that on the training periods, or 0 where it is smaller.
        The calibration's noise ``1/lambda*`` already holds the measured signal's
        out-of-basis part on the training periods (method.md section 4a); a test
        window unlike them has more of it (its series have shapes the basis was not
        built from), and the emulator route's band adds the excess (method.md
        section 6). Zeros without the test window's runs.
        """
        out = np.zeros(self.y_std.shape[0])
        if self.y_test_sim_std is None:
            return out
        train, test = self.basis.residual(self.y_std), self.basis.residual(self.y_test_sim_std)
        for sl in self.outputs.slices.values():
            out[sl] = max(0.0, float(np.mean(test[sl] ** 2) - np.mean(train[sl] ** 2)))
        return out


def runs_to_columns(cut: ArrayLike) -> FloatArray:
    """Runs cut into periods ``(R, n, m*)`` -> ``(n, R m*)`` with run-major columns."""
    arr = np.asarray(cut, dtype=float)
    if arr.ndim != 3:
        raise DataError(f"expected runs cut into periods (R, n, m*), got ndim = {arr.ndim}")
    return arr.transpose(1, 0, 2).reshape(arr.shape[1], -1)


def _runs_array(runs: Mapping[str, ArrayLike], name: str, n_runs: int, n_total: int) -> FloatArray:
    if name not in runs:
        raise DataError(f"simulated output {name!r} missing; the runs have {sorted(runs)}")
    arr = np.asarray(runs[name], dtype=float)
    if arr.shape != (n_runs, n_total):
        raise DataError(
            f"simulated output {name!r} has shape {arr.shape}, expected "
            f"({n_runs} runs, {n_total} samples)",
            hint="drop failed runs from the design as whole runs before assembling",
        )
    return arr


def _series(values: Mapping[str, ArrayLike], name: str, n_total: int, what: str) -> FloatArray:
    if name not in values:
        raise DataError(f"{what} {name!r} missing; got {sorted(values)}")
    arr = np.asarray(values[name], dtype=float)
    if arr.shape != (n_total,):
        raise DataError(f"{what} {name!r} has shape {arr.shape}, expected ({n_total},)")
    return arr


def _check_measured(y_star: FloatArray, names: Sequence[str]) -> None:
    if not np.all(np.isfinite(y_star)):
        raise DataError(
            f"measured output(s) {list(names)} have missing values inside the training periods",
            hint="pass the missing-data mask to layout_periods so such periods are dropped",
        )


def with_history(series: dict[str, FloatArray], history: int, period: int) -> dict[str, FloatArray]:
    """Add each series delayed by 1..``history`` periods (``<name>_lag<k>``)."""
    if history < 0:
        raise ConfigError(f"history must be >= 0 periods, got {history}")
    out = dict(series)
    for k in range(1, history + 1):
        shift = k * period
        for name, values in series.items():
            head = np.full(min(shift, values.size), values[0])
            out[f"{name}_lag{k}"] = np.concatenate([head, values[: values.size - shift]])
    return out


def assemble(
    design: Design,
    runs: Mapping[str, ArrayLike],
    measured: Mapping[str, ArrayLike],
    boundary: Mapping[str, ArrayLike],
    layout: PeriodLayout,
    *,
    outputs: Sequence[str] | None = None,
    variance: float = 0.90,
    components: int | None = None,
    input_variance: float = 0.90,
    history: int = 0,
    lam_shape: float = 5.0,
    lam_rate: float = 5.0,
    scale: Scale = "pointwise",
    noise: Mapping[str, NoiseSpec] | None = None,
) -> Assembled:
    """Cut, standardise and project simulations and measurements (method.md section 2).

    Parameters
    ----------
    design
        The ``R`` parameter sets the simulator was run with (rows = runs).
    runs
        Output name -> simulated series ``(R, n_total)``, in the output's unit
        (e.g. ``heat_flux_in`` [W/m²]).
    measured
        Output name -> measured series ``(n_total,)``, same unit; NaN allowed
        outside the kept training periods.
    boundary
        Boundary-condition name -> series ``(n_total,)`` in its unit (°C,
        W/m², ...); each becomes input columns through its own PCA.
    layout
        Where the warm-up, the training periods and the test window lie.
    outputs
        Outputs to use, in stacking order (default: those of ``measured``).
    variance
        Fraction of the variance of the standardised simulations the output
        basis keeps (ignored when ``components`` is given). [-]
    components
        Exact number ``p`` of basis vectors.
    input_variance
        Fraction of each boundary-condition series' variance kept by its PCA. [-]
    history
        Number of preceding periods whose boundary conditions also enter ``x``
        (as series ``<name>_lag<k>``): a slow wall or room answers to the
        weather of the days before, which the current period alone does not
        show. 0 is the paper's ``x``. Samples before the record start repeat
        the first value.
    lam_shape, lam_rate
        Gamma prior of the simulator precision ``lambda`` before the update of
        eq. 7. [-]
    scale
        ``"pointwise"`` (the paper) or ``"output"`` (one scale per output, so a
        sensor's noise has one size; :func:`bayescal.emulator.basis.standardise`).
    noise
        Output name -> its error model and sensor accuracy (default: white, weak
        prior).

    Returns
    -------
    Assembled
    """
    names = tuple(measured) if outputs is None else tuple(outputs)
    if not names:
        raise ConfigError("no output to calibrate against; give at least one measured output")
    if not boundary:
        raise DataError("no boundary-condition series given; x needs at least one")
    n_runs, n_total = design.runs, layout.n_total
    cuts = {n: layout.cut(_runs_array(runs, n, n_runs, n_total)) for n in names}
    sims = {n: runs_to_columns(c) for n, c in cuts.items()}
    stack = OutputStack(names, tuple(standardise(sims[n], scale) for n in names))
    y_std = stack.apply(sims)
    basis = block_basis(y_std, stack.sizes, variance=variance, components=components)
    meas = {n: _series(measured, n, n_total, "measured output") for n in names}
    y_star_std = stack.apply({n: layout.cut(v) for n, v in meas.items()})
    _check_measured(y_star_std, names)
    y_test_std = stack.apply({n: layout.cut(v, "test") for n, v in meas.items()})
    bc = with_history(
        {n: _series(boundary, n, n_total, "boundary condition") for n in boundary},
        history,
        layout.period,
    )
    inputs = input_pca({n: layout.cut(v).T for n, v in bc.items()}, input_variance)
    x_test = (
        inputs.transform({n: layout.cut(v, "test").T for n, v in bc.items()})
        if layout.test_starts.size
        else np.zeros((0, inputs.x.shape[1]))
    )
    y_test_sim = None
    if layout.test_starts.size:
        sims_test = {
            n: runs_to_columns(layout.cut(_runs_array(runs, n, n_runs, n_total), "test"))
            for n in names
        }
        if all(np.isfinite(v).all() for v in sims_test.values()):
            y_test_sim = stack.apply(sims_test)
    priors = dict(design.priors)
    lower = [p.lower for p in priors.values()]
    upper = [p.upper for p in priors.values()]
    observations = _observations(stack, basis, y_star_std, noise or {})
    return Assembled(
        parameter_names=design.names,
        priors=priors,
        theta_normaliser=Normaliser.from_bounds(lower, upper),
        theta=np.array(design.unit, dtype=float),
        layout=layout,
        outputs=stack,
        basis=basis,
        inputs=inputs,
        x=inputs.x,
        y_std=y_std,
        y_star_std=y_star_std,
        w=basis.weights(y_std),
        w_star=basis.weights(y_star_std),
        lam_prior=basis.lambda_posterior(y_std, lam_shape, lam_rate),
        lam_star_prior=observations.white_prior(0),
        x_test=x_test,
        y_star_test_std=y_test_std,
        observations=observations,
        y_test_sim_std=y_test_sim,
    )


def _observations(
    stack: OutputStack, basis: Basis, y_star: FloatArray, noise: Mapping[str, NoiseSpec]
) -> ObservationModel:
    """Each output's error model: its rows, its bases, its prior in standardised units."""
    unknown = sorted(set(noise) - set(stack.names))
    if unknown:
        raise ConfigError(f"noise given for {unknown}, which are not calibrated outputs")
    outputs = []
    for q, (name, sl) in enumerate(stack.slices.items()):
        spec = noise.get(name, NoiseSpec())
        st = stack.standardisations[q]
        scale = float(np.sqrt(np.mean(st.sd * st.sd)))  # the one scale ("output") or its RMS
        prior = (
            DEFAULT_NOISE_PRIOR if spec.sd is None else noise_prior_from_sd(spec.sd, scale, name)
        )
        bases = tuple(j for j, g in enumerate(basis.groups) if g == q)
        unit = RELATIVE_UNIT if spec.relative else GLOSSARY[name].unit if name in GLOSSARY else ""
        outputs.append(
            OutputNoise(
                name, (sl.start, sl.stop), bases, spec.model, prior, scale, unit, spec.discrepancy
            )
        )
    return ObservationModel(tuple(outputs), basis.k, y_star)
