"""The emulator artefacts: ``emulator.nc`` and ``emulator-cv.npz``.

* :func:`save_emulator` / :func:`load_emulator`: one netCDF file (HDF5 through
  ``h5netcdf``) with the basis, the standardisation, the normalisers, the input
  PCA, the training data, the MAP hyperparameters and their posterior draws;
  names, priors, seeds and a config hash in the attributes. Arrays are stored
  in float64, so a loaded emulator predicts bit for bit what the saved one did.
  Every variable has a ``description`` attribute, and ``units`` where it has
  one unit (the parameters' units are listed in the ``parameter_units``
  attribute, the outputs' in ``output_units``).
* :func:`save_emulator_cv` / :func:`load_emulator_cv`: the leave-one-run-out
  cross-validation (:class:`~bayescal.emulator.gp.LooResult`) as ``.npz``.

Writes go to a hidden temporary file in the destination folder that is then
renamed onto the final name (:mod:`bayescal.atomic`), so a crash never leaves a
half-written artefact.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import xarray as xr

from bayescal.atomic import atomic_write_npz, read_npz
from bayescal.emulator.basis import Basis, InputPCA, Normaliser, SeriesPCA
from bayescal.emulator.gp import ConditionalPieces, Emulator, HyperPriors, LooResult
from bayescal.errors import DataError
from bayescal.store.netcdf import (
    DIMENSIONLESS,
    check_format,
    describe_variables,
    output_unit,
    read_dataset,
    read_output_stack,
    write_dataset,
)

__all__ = [
    "CV_FILE",
    "EMULATOR_FORMAT",
    "FILE",
    "CalibrationInputs",
    "emulator_dataset",
    "load_calibration_inputs",
    "load_emulator",
    "load_emulator_cv",
    "save_emulator",
    "save_emulator_cv",
]

EMULATOR_FORMAT: Final = "bayescal-emulator/1"
#: File names in a study's output folder.
FILE: Final = "emulator.nc"
CV_FILE: Final = "emulator-cv.npz"

_STACKED = "per output in its unit (output_names, output_sizes)"
_DESCRIPTIONS: dict[str, str] = {
    "k": "PCA basis of the standardised simulations (columns: basis vectors)",
    "explained": "fraction of the variance explained by each principal component",
    "std_mean": "point-wise mean of the simulations, " + _STACKED,
    "std_sd": "point-wise standard deviation of the simulations, " + _STACKED,
    "theta_lower": "lower bound of each calibration parameter (its unit: parameter_units)",
    "theta_upper": "upper bound of each calibration parameter (its unit: parameter_units)",
    "theta": "design of the training runs on the normalised scale [0, 1]",
    "x": "variable inputs of the training periods on the normalised scale [0, 1]",
    "w": "basis weights of the training runs and periods",
    "y_std": "standardised simulations (samples x rows)",
    "beta": "correlation parameters beta of each basis GP (MAP)",
    "tau": "precision tau of each basis GP (MAP)",
    "lam": "precision lambda of the simulations outside the basis (MAP)",
    "lam_prior": "Gamma(shape, rate) prior of lambda",
    "hyper_draws": "MCMC draws of the hyperparameters (hyper_names)",
    "hyper_lp": "log posterior at each hyperparameter draw",
    "hyper_acceptance": "acceptance rate per chain and hyperparameter",
    "best_draw": "hyperparameters of the best draw, start of the MAP search",
    "cond_q_t": "eigenvectors of the run correlation per basis (conditional pieces)",
    "cond_q_x": "eigenvectors of the period correlation per basis (conditional pieces)",
    "cond_inv_den": "inverse eigenvalue denominators per basis (conditional pieces)",
    "cond_h": "rotated weights per basis (conditional pieces)",
    "x_lower": "lower bound of each variable input before normalisation",
    "x_upper": "upper bound of each variable input before normalisation",
    "w_star": "basis weights of the measured training periods (eq. 13)",
    "y_star_std": "standardised measured training periods (samples x periods)",
    "lam_star_prior": "Gamma(shape, rate) prior of lambda* after eq. 7",
}


def _shared_unit(names: Sequence[str]) -> str:
    """The outputs' common unit, ``""`` where they differ."""
    units = {output_unit(n) for n in names}
    return units.pop() if len(units) == 1 else ""


def _input_pca_vars(inputs: InputPCA) -> dict[str, tuple[tuple[str, ...], np.ndarray]]:
    out: dict[str, tuple[tuple[str, ...], np.ndarray]] = {
        "x_lower": (("x_input",), inputs.normaliser.lower),
        "x_upper": (("x_input",), inputs.normaliser.upper),
    }
    for i, sp in enumerate(inputs.series):
        out[f"bc{i}_mean"] = ((f"bc{i}_sample",), sp.mean)
        out[f"bc{i}_directions"] = ((f"bc{i}_pc", f"bc{i}_sample"), sp.directions)
        out[f"bc{i}_explained"] = ((f"bc{i}_pc",), sp.explained)
    return out


def _attributes(em: Emulator, parameter_units: Sequence[str]) -> dict[str, tuple[str, str]]:
    stacked = _shared_unit(em.outputs.names)
    units = {name: "" for name in _DESCRIPTIONS}
    units |= {"std_mean": stacked, "std_sd": stacked, "explained": DIMENSIONLESS}
    units |= {"theta": DIMENSIONLESS, "x": DIMENSIONLESS, "y_std": DIMENSIONLESS}
    if len(set(parameter_units)) == 1 and parameter_units[0]:
        units |= {"theta_lower": parameter_units[0], "theta_upper": parameter_units[0]}
    out = {name: (units[name], text) for name, text in _DESCRIPTIONS.items()}
    for i, sp in enumerate(em.inputs.series):
        unit = output_unit(sp.name)
        out[f"bc{i}_mean"] = (unit, f"mean of the boundary condition {sp.name} per sample")
        out[f"bc{i}_directions"] = ("", f"principal directions of {sp.name} over a period")
        out[f"bc{i}_explained"] = (DIMENSIONLESS, f"variance of {sp.name} explained per PC")
    return out


@dataclass(frozen=True)
class CalibrationInputs:
    """What a calibration needs beside the emulator, as stored in ``emulator.nc``.

    With the emulator and the theta* priors (``design.csv``) it rebuilds the
    calibration target from files alone
    (:func:`bayescal.calibration.target.build_target`).

    Attributes
    ----------
    w_star
        Observed weights of the training periods ``(m*, p)`` (eq. 13). [-]
    y_star_std
        Standardised measured training periods ``(N, m*)``. [-]
    lam_star_prior
        Gamma ``(shape, rate)`` of ``lambda*`` after eq. 7.
    """

    w_star: np.ndarray
    y_star_std: np.ndarray
    lam_star_prior: tuple[float, float]


def emulator_dataset(
    emulator: Emulator,
    config_hash: str = "",
    parameter_units: Sequence[str] = (),
    inputs: CalibrationInputs | None = None,
) -> xr.Dataset:
    """The emulator as an ``xarray.Dataset`` (what :func:`save_emulator` writes).

    Parameters
    ----------
    emulator
        The trained emulator.
    config_hash
        Hash of the study configuration (recorded, not checked).
    parameter_units
        Unit of each calibration parameter, in the emulator's parameter order
        (recorded in the ``parameter_units`` attribute; empty where unknown).
    inputs
        The measured side of the calibration (stored as ``w_star``,
        ``y_star_std`` and ``lam_star_prior``), or ``None``.
    """
    em = emulator
    units = list(parameter_units) or [""] * len(em.parameter_names)
    variables: dict[str, tuple[tuple[str, ...], Any]] = {
        "k": (("sample", "basis"), em.basis.k),
        "explained": (("component",), em.basis.explained),
        "std_mean": (("sample",), em.outputs.mean),
        "std_sd": (("sample",), em.outputs.sd),
        "theta_lower": (("parameter",), em.theta_normaliser.lower),
        "theta_upper": (("parameter",), em.theta_normaliser.upper),
        "theta": (("run", "parameter"), em.theta),
        "x": (("period", "x_input"), em.x),
        "w": (("row", "basis"), em.w),
        "y_std": (("sample", "row"), em.y_std),
        "beta": (("basis", "input"), em.beta),
        "tau": (("basis",), em.tau),
        "lam": ((), em.lam),
        "lam_prior": (("gamma_parameter",), np.asarray(em.lam_prior)),
        "hyper_draws": (("chain", "draw", "hyper"), em.hyper_draws),
        "hyper_lp": (("chain", "draw"), em.hyper_lp),
        "hyper_acceptance": (("chain", "hyper"), em.hyper_acceptance),
        "best_draw": (("hyper",), em.best_draw),
        "cond_q_t": (("basis", "run", "run_"), em.pieces.q_t),
        "cond_q_x": (("basis", "period", "period_"), em.pieces.q_x),
        "cond_inv_den": (("basis", "run", "period"), em.pieces.inv_den),
        "cond_h": (("basis", "run", "period"), em.pieces.h),
        **_input_pca_vars(em.inputs),
    }
    if inputs is not None:
        variables["w_star"] = (("period", "basis"), inputs.w_star)
        variables["y_star_std"] = (("sample", "period"), inputs.y_star_std)
        variables["lam_star_prior"] = (("gamma_parameter",), np.asarray(inputs.lam_star_prior))
    attrs = {
        "format": EMULATOR_FORMAT,
        "parameter_names": json.dumps(list(em.parameter_names)),
        "parameter_units": json.dumps(units, ensure_ascii=False),
        "input_labels": json.dumps(list(em.input_labels)),
        "hyper_names": json.dumps(em.hyper_names),
        "output_names": json.dumps(list(em.outputs.names)),
        "output_sizes": json.dumps(list(em.outputs.sizes)),
        "output_units": json.dumps([output_unit(n) for n in em.outputs.names], ensure_ascii=False),
        "series_names": json.dumps([sp.name for sp in em.inputs.series]),
        "basis_n_periods": em.basis.n_periods,
        "hyper_priors": json.dumps(asdict(em.hyper_priors)),
        "seed": em.seed,
        "log_post_best": em.log_post_best,
        "log_post_map": em.log_post_map,
        "config_hash": config_hash,
    }
    ds = xr.Dataset({k: xr.Variable(*v) for k, v in variables.items()}, attrs=attrs)
    return describe_variables(ds, _attributes(em, units))


def save_emulator(
    emulator: Emulator,
    path: str | os.PathLike[str],
    config_hash: str = "",
    parameter_units: Sequence[str] = (),
    inputs: CalibrationInputs | None = None,
) -> Path:
    """Write an emulator to netCDF atomically.

    Parameters
    ----------
    emulator
        The trained emulator.
    path
        Destination file (``.nc``); its folder is created if missing.
    config_hash
        Hash of the study configuration that produced it (recorded, not checked).
    parameter_units
        Unit of each calibration parameter (see :func:`emulator_dataset`).
    inputs
        What the calibration needs beside the emulator (see :class:`CalibrationInputs`).

    Returns
    -------
    pathlib.Path
        The final path.
    """
    return write_dataset(emulator_dataset(emulator, config_hash, parameter_units, inputs), path)


def load_calibration_inputs(path: str | os.PathLike[str]) -> CalibrationInputs:
    """The measured side of the calibration stored with an emulator.

    Raises
    ------
    bayescal.errors.DataError
        If the file is not an emulator artefact or was saved without them.
    """
    ds = read_dataset(path)
    check_format(ds, EMULATOR_FORMAT, path)
    if "w_star" not in ds:
        raise DataError(
            f"{os.fspath(path)} holds no calibration inputs (written before they were saved)",
            hint="re-run the emulator stage: bayescal run --from emulator",
        )
    prior = ds["lam_star_prior"].values
    return CalibrationInputs(
        ds["w_star"].values, ds["y_star_std"].values, (float(prior[0]), float(prior[1]))
    )


def _inputs(ds: xr.Dataset, x: np.ndarray) -> InputPCA:
    series = []
    for i, name in enumerate(json.loads(ds.attrs["series_names"])):
        series.append(
            SeriesPCA(
                name,
                ds[f"bc{i}_mean"].values,
                ds[f"bc{i}_directions"].values,
                ds[f"bc{i}_explained"].values,
            )
        )
    norm = Normaliser(ds["x_lower"].values, ds["x_upper"].values)
    return InputPCA(tuple(series), norm, x)


def load_emulator(path: str | os.PathLike[str]) -> Emulator:
    """Read an emulator written by :func:`save_emulator`.

    Raises
    ------
    bayescal.errors.DataError
        If the file is missing or is not an emulator artefact.
    """
    ds = read_dataset(path)
    check_format(ds, EMULATOR_FORMAT, path)
    v = {name: ds[name].values for name in ds.data_vars}
    basis = Basis(v["k"], v["explained"], int(ds.attrs["basis_n_periods"]))
    return Emulator(
        parameter_names=tuple(json.loads(ds.attrs["parameter_names"])),
        input_labels=tuple(json.loads(ds.attrs["input_labels"])),
        theta_normaliser=Normaliser(v["theta_lower"], v["theta_upper"]),
        outputs=read_output_stack(ds),
        basis=basis,
        inputs=_inputs(ds, v["x"]),
        theta=v["theta"],
        x=v["x"],
        w=v["w"],
        y_std=v["y_std"],
        beta=v["beta"],
        tau=v["tau"],
        lam=float(v["lam"]),
        lam_prior=(float(v["lam_prior"][0]), float(v["lam_prior"][1])),
        hyper_draws=v["hyper_draws"],
        hyper_lp=v["hyper_lp"],
        hyper_acceptance=v["hyper_acceptance"],
        best_draw=v["best_draw"],
        log_post_best=float(ds.attrs["log_post_best"]),
        log_post_map=float(ds.attrs["log_post_map"]),
        seed=int(ds.attrs["seed"]),
        hyper_priors=HyperPriors(**json.loads(ds.attrs["hyper_priors"])),
        conditional=ConditionalPieces(v["cond_q_t"], v["cond_q_x"], v["cond_inv_den"], v["cond_h"]),
    )


def save_emulator_cv(loo: LooResult, path: str | os.PathLike[str]) -> Path:
    """Write the leave-one-run-out cross-validation as ``.npz`` atomically.

    Arrays ``names``, ``rmse`` and ``output_sd`` (per output, in its unit),
    ``rmse_run`` ``(R, n_outputs)`` and ``z`` (standardised residuals). [-]
    """
    names = list(loo.rmse)
    return atomic_write_npz(
        path,
        {
            "names": np.array(names),
            "rmse": np.array([loo.rmse[n] for n in names]),
            "output_sd": np.array([loo.output_sd[n] for n in names]),
            "rmse_run": loo.rmse_run,
            "z": loo.z,
        },
    )


def load_emulator_cv(path: str | os.PathLike[str]) -> LooResult:
    """Read the cross-validation written by :func:`save_emulator_cv`."""
    a = read_npz(path)
    names = [str(n) for n in a["names"]]
    return LooResult(
        rmse=dict(zip(names, map(float, a["rmse"]), strict=True)),
        output_sd=dict(zip(names, map(float, a["output_sd"]), strict=True)),
        rmse_run=a["rmse_run"],
        z=a["z"],
    )
