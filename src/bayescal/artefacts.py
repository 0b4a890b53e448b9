"""Emulator and posterior artefacts as netCDF (xarray / ArviZ), written atomically.

* :func:`save_emulator` / :func:`load_emulator`: one netCDF file (HDF5 through
  ``h5netcdf``) with the basis, the standardisation, the normalisers, the input
  PCA, the training data, the MAP hyperparameters and their posterior draws;
  names, priors, seeds and a config hash in the attributes. Arrays are stored
  in float64, so a loaded emulator predicts bit for bit what the saved one did.
* :func:`save_posterior` / :func:`load_posterior`: ArviZ ``InferenceData``
  (``posterior`` in physical units with ``lambda`` and ``lambda_star``,
  ``sample_stats.lp``) plus a ``bayescal`` group with the normalised draws,
  acceptance rates, priors, seed and config hash.

Writes go to a hidden temporary file in the destination folder that is then
renamed onto the final name (:mod:`bayescal.atomic`), so a crash never leaves a
half-written artefact.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any, Final

import numpy as np
import xarray as xr

from bayescal.atomic import atomic_write_path
from bayescal.calibration.posterior import LAMBDA_NAMES, Posterior
from bayescal.design import prior_from_spec
from bayescal.emulator.assemble import OutputStack
from bayescal.emulator.basis import Basis, InputPCA, Normaliser, SeriesPCA, Standardisation
from bayescal.emulator.gp import ConditionalPieces, Emulator, HyperPriors
from bayescal.errors import DataError

__all__ = ["load_emulator", "load_posterior", "save_emulator", "save_posterior"]

EMULATOR_FORMAT = "bayescal-emulator/1"
POSTERIOR_FORMAT = "bayescal-posterior/1"
ENGINE: Final = "h5netcdf"


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


def emulator_dataset(emulator: Emulator, config_hash: str = "") -> xr.Dataset:
    """The emulator as an ``xarray.Dataset`` (what :func:`save_emulator` writes)."""
    em = emulator
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
    attrs = {
        "format": EMULATOR_FORMAT,
        "parameter_names": json.dumps(list(em.parameter_names)),
        "input_labels": json.dumps(list(em.input_labels)),
        "hyper_names": json.dumps(em.hyper_names),
        "output_names": json.dumps(list(em.outputs.names)),
        "output_sizes": json.dumps(list(em.outputs.sizes)),
        "series_names": json.dumps([sp.name for sp in em.inputs.series]),
        "basis_n_periods": em.basis.n_periods,
        "hyper_priors": json.dumps(asdict(em.hyper_priors)),
        "seed": em.seed,
        "log_post_best": em.log_post_best,
        "log_post_map": em.log_post_map,
        "config_hash": config_hash,
    }
    return xr.Dataset({k: xr.Variable(*v) for k, v in variables.items()}, attrs=attrs)


def save_emulator(emulator: Emulator, path: str | os.PathLike[str], config_hash: str = "") -> Path:
    """Write an emulator to netCDF atomically.

    Parameters
    ----------
    emulator
        The trained emulator.
    path
        Destination file (``.nc``); its folder is created if missing.
    config_hash
        Hash of the study configuration that produced it (recorded, not checked).

    Returns
    -------
    pathlib.Path
        The final path.
    """
    ds = emulator_dataset(emulator, config_hash)

    def write(temp: Path) -> None:
        ds.to_netcdf(os.fspath(temp), engine=ENGINE)

    return atomic_write_path(path, write)


def _read(path: str | os.PathLike[str], group: str | None = None) -> xr.Dataset:
    if not Path(path).is_file():
        raise DataError(f"artefact {os.fspath(path)!r} does not exist")
    try:
        with xr.open_dataset(path, engine=ENGINE, group=group) as ds:
            return ds.load()
    except OSError as exc:
        where = f"group {group!r} of " if group else ""
        raise DataError(
            f"cannot read {where}artefact {os.fspath(path)!r}: {exc}",
            hint="the file is not a bayescal artefact of this kind; re-run the stage",
        ) from exc


def _check_format(ds: xr.Dataset, expected: str, path: str | os.PathLike[str]) -> None:
    found = ds.attrs.get("format")
    if found != expected:
        raise DataError(
            f"{os.fspath(path)}: expected a {expected!r} artefact, found format {found!r}",
            hint="re-run the stage that writes it",
        )


def _outputs(ds: xr.Dataset) -> OutputStack:
    names = json.loads(ds.attrs["output_names"])
    sizes = json.loads(ds.attrs["output_sizes"])
    bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    mean, sd = ds["std_mean"].values, ds["std_sd"].values
    stds = tuple(
        Standardisation(mean[bounds[q] : bounds[q + 1]], sd[bounds[q] : bounds[q + 1]])
        for q in range(len(names))
    )
    return OutputStack(tuple(names), stds)


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
    ds = _read(path)
    _check_format(ds, EMULATOR_FORMAT, path)
    v = {name: ds[name].values for name in ds.data_vars}
    basis = Basis(v["k"], v["explained"], int(ds.attrs["basis_n_periods"]))
    return Emulator(
        parameter_names=tuple(json.loads(ds.attrs["parameter_names"])),
        input_labels=tuple(json.loads(ds.attrs["input_labels"])),
        theta_normaliser=Normaliser(v["theta_lower"], v["theta_upper"]),
        outputs=_outputs(ds),
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


def save_posterior(
    posterior: Posterior, path: str | os.PathLike[str], config_hash: str = ""
) -> Path:
    """Write a calibration posterior to netCDF (ArviZ groups + ``bayescal``) atomically.

    Parameters
    ----------
    posterior
        The calibration result.
    path
        Destination file (``.nc``).
    config_hash
        Hash of the study configuration (recorded, not checked).

    Returns
    -------
    pathlib.Path
        The final path.
    """
    idata = posterior.inference_data()
    extra = xr.Dataset(
        {
            "unit_draws": (("chain", "draw", "parameter"), posterior.unit_draws),
            "acceptance": (("chain", "coordinate"), posterior.acceptance),
        },
        attrs={
            "format": POSTERIOR_FORMAT,
            "names": json.dumps(list(posterior.names)),
            "priors": json.dumps({n: p.spec() for n, p in posterior.priors.items()}),
            "seed": posterior.seed,
            "algebra": posterior.algebra,
            "config_hash": config_hash,
        },
    )
    idata.add_groups({"bayescal": extra})

    def write(temp: Path) -> None:
        idata.to_netcdf(os.fspath(temp), engine=ENGINE)

    return atomic_write_path(path, write)


def load_posterior(path: str | os.PathLike[str]) -> Posterior:
    """Read a posterior written by :func:`save_posterior` (diagnostics recomputed).

    Raises
    ------
    bayescal.errors.DataError
        If the file is missing or is not a posterior artefact.
    """
    extra = _read(path, group="bayescal")
    _check_format(extra, POSTERIOR_FORMAT, path)
    post = _read(path, group="posterior")
    stats = _read(path, group="sample_stats")
    priors = {n: prior_from_spec(**spec) for n, spec in json.loads(extra.attrs["priors"]).items()}
    return Posterior.build(
        names=json.loads(extra.attrs["names"]),
        priors=priors,
        unit_draws=extra["unit_draws"].values,
        lam=post[LAMBDA_NAMES[0]].values,
        lam_star=post[LAMBDA_NAMES[1]].values,
        log_density=stats["lp"].values,
        acceptance=extra["acceptance"].values,
        seed=int(extra.attrs["seed"]),
        algebra=str(extra.attrs["algebra"]),
    )
