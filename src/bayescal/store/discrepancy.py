"""The difference process: ``discrepancy.nc``, written atomically.

One ``xarray.Dataset`` (HDF5 through ``h5netcdf``, as the other artefacts)
holds the estimate ``delta`` (physical units), the standardisation, the GP of
``Delta`` with its factorised covariances (so that a loaded discrepancy
predicts bit for bit what the saved one did), the theta* draws of the phase
(normalised, with the fixed precisions and error parameters ``aux``, log
density and acceptance) and, in the attributes, names, priors, seeds,
settings and whether the phase converged. Variables carry
``description`` attributes, and ``units`` where they have one unit. The write
goes through :func:`bayescal.atomic.atomic_write_path` (temporary file, fsync,
rename).
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any, Final

import numpy as np
import xarray as xr

from bayescal.calibration.posterior import Posterior
from bayescal.design import prior_from_spec
from bayescal.discrepancy.delta_gp import DeltaGP
from bayescal.discrepancy.model import Discrepancy
from bayescal.discrepancy.phase import FixedPrecisions
from bayescal.store.netcdf import (
    DIMENSIONLESS,
    check_format,
    describe_variables,
    output_unit,
    read_dataset,
    read_output_stack,
    write_dataset,
)
from bayescal.store.posterior import output_noise_from_json

__all__ = [
    "DISCREPANCY_FORMAT",
    "FILE",
    "discrepancy_dataset",
    "load_discrepancy",
    "save_discrepancy",
]

DISCREPANCY_FORMAT: Final = "bayescal-discrepancy/1"
#: File name in a study's output folder.
FILE: Final = "discrepancy.nc"

_GP_DIMS: dict[str, tuple[str, ...]] = {
    "basis": ("sample", "component"),
    "weights": ("period", "component"),
    "beta": ("component", "x_input"),
    "tau": ("component",),
    "nugget": ("component",),
    "coef": ("component", "regressor"),
    "chol": ("component", "period", "period_"),
    "alpha": ("component", "period"),
    "cinv_h": ("component", "period", "regressor"),
    "hch_chol": ("component", "regressor", "regressor_"),
}


def discrepancy_dataset(d: Discrepancy, config_hash: str = "") -> xr.Dataset:
    """The discrepancy as an ``xarray.Dataset`` (what :func:`save_discrepancy` writes)."""
    post = d.posterior
    variables: dict[str, tuple[tuple[str, ...], Any]] = {
        "delta": (("sample", "period"), d.delta),
        "x": (("period", "x_input"), d.x),
        "std_mean": (("sample",), d.outputs.mean),
        "std_sd": (("sample",), d.outputs.sd),
        "unit_draws": (("chain", "draw", "parameter"), post.unit_draws),
        "aux_draws": (("chain", "draw", "aux"), post.aux),
        "log_density": (("chain", "draw"), post.log_density),
        "acceptance": (("chain", "coordinate"), post.acceptance),
    }
    for name, dims in _GP_DIMS.items():
        variables[f"gp_{name}"] = (dims, getattr(d.gp, name))
    attrs = {
        "format": DISCREPANCY_FORMAT,
        "sign": "delta = observation - model",
        "output_names": json.dumps(list(d.outputs.names)),
        "output_sizes": json.dumps(list(d.outputs.sizes)),
        "names": json.dumps(list(post.names)),
        "priors": json.dumps({n: p.spec() for n, p in post.priors.items()}),
        "seed": post.seed,
        "algebra": post.algebra,
        "aux_names": json.dumps(list(post.aux_names)),
        "noise": json.dumps([dataclasses.asdict(o) for o in post.noise]),
        "fixed": json.dumps(dataclasses.asdict(d.fixed)),
        "realisations": d.realisations,
        "update_interval": d.update_interval,
        "updates": d.updates,
        "converged": "unknown" if d.converged is None else str(bool(d.converged)).lower(),
        "trend": d.gp.trend,
        "config_hash": config_hash,
    }
    ds = xr.Dataset({k: xr.Variable(*v) for k, v in variables.items()}, attrs=attrs)
    return describe_variables(ds, _attributes(d))


def _attributes(d: Discrepancy) -> dict[str, tuple[str, str]]:
    units = {output_unit(n) for n in d.outputs.names}
    unit = units.pop() if len(units) == 1 else ""
    stacked = "per output in its unit (output_names, output_sizes)"
    return {
        "delta": (
            unit,
            "estimate of Delta = observation - model per sample and training period, " + stacked,
        ),
        "x": (DIMENSIONLESS, "variable inputs of the training periods, normalised"),
        "std_mean": (unit, "point-wise mean of the simulations, " + stacked),
        "std_sd": (unit, "point-wise standard deviation of the simulations, " + stacked),
        "unit_draws": (DIMENSIONLESS, "theta* of the discrepancy phase, normalised to [0, 1]"),
        "aux_draws": (
            DIMENSIONLESS,
            "lambda, lambda* per output, AR(1) coefficients and discrepancy variances "
            "(aux_names), fixed at their calibration means",
        ),
        "log_density": ("", "log posterior density (up to a constant) at the draw"),
        "acceptance": (DIMENSIONLESS, "acceptance rate per chain and sampled coordinate"),
        **{f"gp_{name}": ("", f"GP of Delta: {name}") for name in _GP_DIMS},
    }


def save_discrepancy(
    discrepancy: Discrepancy, path: str | os.PathLike[str], config_hash: str = ""
) -> Path:
    """Write a discrepancy to netCDF atomically.

    Parameters
    ----------
    discrepancy
        The estimated difference process.
    path
        Destination file (``.nc``); its folder is created if missing.
    config_hash
        Hash of the study configuration that produced it (recorded, not checked).

    Returns
    -------
    pathlib.Path
        The final path.
    """
    return write_dataset(discrepancy_dataset(discrepancy, config_hash), path)


def load_discrepancy(path: str | os.PathLike[str]) -> Discrepancy:
    """Read a discrepancy written by :func:`save_discrepancy` (diagnostics recomputed).

    Raises
    ------
    bayescal.errors.DataError
        If the file is missing or is not a discrepancy artefact.
    """
    ds = read_dataset(path)
    check_format(ds, DISCREPANCY_FORMAT, path)
    v = {name: np.asarray(ds[name].values) for name in ds.data_vars}
    priors = {n: prior_from_spec(**spec) for n, spec in json.loads(ds.attrs["priors"]).items()}
    names = json.loads(ds.attrs["names"])
    common = {
        "names": names,
        "priors": priors,
        "unit_draws": v["unit_draws"],
        "log_density": v["log_density"],
        "acceptance": v["acceptance"],
        "seed": int(ds.attrs["seed"]),
        "algebra": str(ds.attrs["algebra"]),
    }
    if "aux_draws" in v:
        noise = tuple(output_noise_from_json(o) for o in json.loads(ds.attrs.get("noise", "[]")))
        aux_names = json.loads(ds.attrs["aux_names"])
        post = Posterior.build(**common, aux=v["aux_draws"], aux_names=aux_names, noise=noise)
        spec = json.loads(ds.attrs["fixed"])
        fixed = FixedPrecisions(
            lam=float(spec["lam"]),
            lam_star=tuple(float(x) for x in spec["lam_star"]),
            phi=tuple(float(x) for x in spec["phi"]),
            delta_rel=tuple(float(x) for x in spec["delta_rel"]),
        )
    else:  # written before the fixed precisions were recorded per output (one white output)
        post = Posterior.build(**common, lam=v["lam"], lam_star=v["lam_star"])
        fixed = FixedPrecisions(float(ds.attrs["lam_fixed"]), (float(ds.attrs["lam_star_fixed"]),))
    converged = {"true": True, "false": False}.get(str(ds.attrs.get("converged", "unknown")))
    gp = DeltaGP(
        trend=str(ds.attrs["trend"]), x=v["x"], **{name: v[f"gp_{name}"] for name in _GP_DIMS}
    )
    return Discrepancy(
        outputs=read_output_stack(ds),
        x=v["x"],
        delta=v["delta"],
        gp=gp,
        posterior=post,
        fixed=fixed,
        realisations=int(ds.attrs["realisations"]),
        update_interval=int(ds.attrs["update_interval"]),
        updates=int(ds.attrs.get("updates", 0)),
        converged=converged,
    )
