"""The difference process: ``discrepancy.nc``, written atomically.

One ``xarray.Dataset`` (HDF5 through ``h5netcdf``, as the other artefacts)
holds the estimate ``delta`` (physical units), the standardisation, the GP of
``Delta`` with its factorised covariances (so that a loaded discrepancy
predicts bit for bit what the saved one did), the theta* draws of the phase
(normalised, with ``lambda``, ``lambda*``, log density and acceptance) and, in
the attributes, names, priors, seeds and settings. Variables carry
``description`` attributes, and ``units`` where they have one unit. The write
goes through :func:`bayescal.atomic.atomic_write_path` (temporary file, fsync,
rename).
"""

from __future__ import annotations

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
        "lam": (("chain", "draw"), post.lam),
        "lam_star": (("chain", "draw"), post.lam_star),
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
        "lam_fixed": d.lam,
        "lam_star_fixed": d.lam_star,
        "realisations": d.realisations,
        "update_interval": d.update_interval,
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
        "lam": (DIMENSIONLESS, "precision lambda of the simulations outside the basis"),
        "lam_star": (DIMENSIONLESS, "precision lambda* of the measurement error"),
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
    post = Posterior.build(
        names=json.loads(ds.attrs["names"]),
        priors=priors,
        unit_draws=v["unit_draws"],
        lam=v["lam"],
        lam_star=v["lam_star"],
        log_density=v["log_density"],
        acceptance=v["acceptance"],
        seed=int(ds.attrs["seed"]),
        algebra=str(ds.attrs["algebra"]),
    )
    gp = DeltaGP(
        trend=str(ds.attrs["trend"]), x=v["x"], **{name: v[f"gp_{name}"] for name in _GP_DIMS}
    )
    return Discrepancy(
        outputs=read_output_stack(ds),
        x=v["x"],
        delta=v["delta"],
        gp=gp,
        posterior=post,
        lam=float(ds.attrs["lam_fixed"]),
        lam_star=float(ds.attrs["lam_star_fixed"]),
        realisations=int(ds.attrs["realisations"]),
        update_interval=int(ds.attrs["update_interval"]),
    )
