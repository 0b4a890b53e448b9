"""The calibration posterior: ``posterior.nc`` and ``posterior-summary.csv``.

``posterior.nc`` opens as a user expects. Its **root group** is a flat dataset
of the draws in physical units, one variable per calibration parameter with
dimensions ``(chain, draw)``, plus ``lambda``, the observation precisions
(``lambda_star``, or ``lambda_star_<output>`` with several outputs), the AR(1)
coefficients (``phi[_<output>]``) where an output has AR(1) errors, each
output's noise standard deviation in its unit (``noise_sd[_<output>]``) and
``lp`` (the log posterior), each with ``units`` and ``description`` (and
``long_name``) attributes::

    import xarray as xr
    ds = xr.open_dataset("out/posterior.nc")     # k_cb, cp_cb, ..., lambda, lp
    ds["k_cb"].attrs["units"]                     # 'W/(m·K)'

Beside it are the ArviZ groups (``posterior`` with theta*, ``lambda`` and
``lambda_star``; ``sample_stats`` with ``lp``), so ``arviz.from_netcdf``
reads the same file as an ``InferenceData``, and a ``bayescal`` group with the
normalised draws, the acceptance rates, the priors (with units and
descriptions), the seed and the config hash, from which :func:`load_posterior`
rebuilds the :class:`~bayescal.calibration.posterior.Posterior`.

``posterior-summary.csv`` (:func:`posterior_summary`) is
:meth:`Posterior.summary <bayescal.calibration.posterior.Posterior.summary>`
with two more columns, ``unit`` and ``description``.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any, Final

import numpy as np
import pandas as pd
import xarray as xr

from bayescal.atomic import atomic_write_path, atomic_write_text
from bayescal.calibration.posterior import LAMBDA_NAMES, Derived, Posterior
from bayescal.design import prior_from_spec
from bayescal.emulator.noise import OutputNoise
from bayescal.store.netcdf import (
    DIMENSIONLESS,
    ENGINE,
    check_format,
    describe_variables,
    read_dataset,
)

__all__ = [
    "FILE",
    "POSTERIOR_FORMAT",
    "SUMMARY_FILE",
    "load_posterior",
    "output_noise_from_json",
    "posterior_dataset",
    "posterior_quantities",
    "posterior_summary",
    "save_posterior",
    "save_posterior_summary",
    "variable_attributes",
]

POSTERIOR_FORMAT: Final = "bayescal-posterior/1"
#: File names in a study's output folder.
FILE: Final = "posterior.nc"
SUMMARY_FILE: Final = "posterior-summary.csv"
LOG_DENSITY: Final = "lp"


def _aux_description(name: str) -> str:
    record, _, own = name.rpartition(":")
    if record:  # a joint calibration's record (bayescal joint)
        return f"{_aux_description(own)}, record {record}"
    if name == "lambda":
        return "precision lambda of the simulations outside the PCA basis (standardised units)"
    if name.startswith("lambda_star"):
        which = name.removeprefix("lambda_star").lstrip("_") or "the output"
        return f"precision lambda* of the measurement error of {which} (standardised units)"
    if name.startswith("delta_rel"):
        which = name.removeprefix("delta_rel").lstrip("_") or "the output"
        return (
            f"variance of the model discrepancy of {which} over the periods' conditions, "
            "relative to the emulator's prior variance of a weight"
        )
    if name.startswith("delta_ind"):
        which = name.removeprefix("delta_ind").lstrip("_") or "the output"
        return (
            f"variance of the model discrepancy of {which} independent between periods, "
            "relative to the emulator's prior variance of a weight"
        )
    which = name.removeprefix("phi").lstrip("_") or "the output"
    return f"AR(1) coefficient of the measurement errors of {which} within a period"


def _noise_name(posterior: Posterior, output: str) -> str:
    return "noise_sd" if len(posterior.noise) == 1 else f"noise_sd_{output}"


def variable_attributes(posterior: Posterior) -> dict[str, tuple[str, str]]:
    """Name -> ``(unit, description)`` of every column of the draws, the noise SDs and ``lp``.

    theta* in the parameter's unit and with its description (from the priors;
    ``""`` where the study gave none), ``lambda``, ``lambda_star`` and ``phi``
    dimensionless (``"1"``), ``noise_sd`` in the output's unit.
    """
    out = {name: (prior.unit, prior.description) for name, prior in posterior.priors.items()}
    out |= {name: (DIMENSIONLESS, _aux_description(name)) for name in posterior.aux_names}
    for o in posterior.noise:
        text = (
            f"standard deviation of the measurement error of {o.name}: the sensor's noise "
            "and the part of the measurement the output basis cannot represent"
        )
        out[_noise_name(posterior, o.name)] = (o.unit, text)
    out |= {name: (d.unit, d.description) for name, d in posterior.derived.items()}
    out[LOG_DENSITY] = ("", "log posterior density (up to a constant) at the draw")
    return out


def posterior_dataset(posterior: Posterior) -> xr.Dataset:
    """The flat view of the draws written to the root group of ``posterior.nc``.

    One variable per calibration parameter (physical units), ``lambda``,
    ``lambda_star`` and ``lp``, each ``(chain, draw)``, with ``units``,
    ``long_name`` and ``description`` attributes.
    """
    draws = posterior.all_draws()
    chains, n_draws = draws.shape[:2]
    data = {name: (("chain", "draw"), draws[..., k]) for k, name in enumerate(posterior.all_names)}
    for output, sd in posterior.noise_sd().items():
        data[_noise_name(posterior, output)] = (("chain", "draw"), sd)
    for name, derived in posterior.derived.items():
        data[name] = (("chain", "draw"), derived.draws)
    data[LOG_DENSITY] = (("chain", "draw"), posterior.log_density)
    ds = xr.Dataset(
        data,
        coords={"chain": np.arange(chains), "draw": np.arange(n_draws)},
        attrs={
            "title": "bayescal calibration posterior",
            "description": "draws of theta* (physical units), lambda and lambda* with their "
            "log posterior; the ArviZ groups posterior and sample_stats hold the same "
            "draws for arviz.from_netcdf",
        },
    )
    return describe_variables(ds, variable_attributes(posterior), long_names=True)


def save_posterior(
    posterior: Posterior, path: str | os.PathLike[str], config_hash: str = ""
) -> Path:
    """Write a calibration posterior to netCDF atomically (see the module docstring).

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
    attributes = variable_attributes(posterior)
    for group in ("posterior", "sample_stats"):
        describe_variables(idata[group], attributes)
    extra = xr.Dataset(
        {
            "unit_draws": (("chain", "draw", "parameter"), posterior.unit_draws),
            "acceptance": (("chain", "coordinate"), posterior.acceptance),
        },
        attrs={
            "format": POSTERIOR_FORMAT,
            "names": json.dumps(list(posterior.names)),
            "aux_names": json.dumps(list(posterior.aux_names)),
            "noise": json.dumps([dataclasses.asdict(o) for o in posterior.noise]),
            "derived": json.dumps(
                {n: [d.unit, d.description] for n, d in posterior.derived.items()},
                ensure_ascii=False,
            ),
            "priors": json.dumps({n: p.spec() for n, p in posterior.priors.items()}),
            "seed": posterior.seed,
            "algebra": posterior.algebra,
            "config_hash": config_hash,
        },
    )
    describe_variables(
        extra,
        {
            "unit_draws": (DIMENSIONLESS, "theta* on the normalised scale [0, 1] of the bounds"),
            "acceptance": (DIMENSIONLESS, "acceptance rate per chain and sampled coordinate"),
        },
    )
    idata.add_groups({"bayescal": extra})
    flat = posterior_dataset(posterior)

    def write(temp: Path) -> None:
        idata.to_netcdf(os.fspath(temp), engine=ENGINE)
        flat.to_netcdf(os.fspath(temp), mode="a", engine=ENGINE)

    return atomic_write_path(path, write)


def load_posterior(path: str | os.PathLike[str]) -> Posterior:
    """Read a posterior written by :func:`save_posterior` (diagnostics recomputed).

    Raises
    ------
    bayescal.errors.DataError
        If the file is missing or is not a posterior artefact.
    """
    extra = _metadata(path)
    post = read_dataset(path, group="posterior")
    stats = read_dataset(path, group="sample_stats")
    priors = {n: prior_from_spec(**spec) for n, spec in json.loads(extra.attrs["priors"]).items()}
    aux_names = json.loads(extra.attrs.get("aux_names", json.dumps(LAMBDA_NAMES)))
    noise = tuple(output_noise_from_json(o) for o in json.loads(extra.attrs.get("noise", "[]")))
    specs = json.loads(extra.attrs.get("derived", "{}"))
    derived = {}
    if specs:
        flat = read_dataset(path)
        derived = {n: Derived(flat[n].values, u, d) for n, (u, d) in specs.items()}
    return Posterior.build(
        names=json.loads(extra.attrs["names"]),
        priors=priors,
        unit_draws=extra["unit_draws"].values,
        log_density=stats[LOG_DENSITY].values,
        acceptance=extra["acceptance"].values,
        seed=int(extra.attrs["seed"]),
        algebra=str(extra.attrs["algebra"]),
        aux=np.stack([post[n].values for n in aux_names], axis=-1),
        aux_names=aux_names,
        noise=noise,
    ).with_derived(derived)


def posterior_quantities(path: str | os.PathLike[str]) -> tuple[str, ...]:
    """The calibration parameters and derived quantities of a posterior file, in order,
    from its metadata alone (no draws summarised, no diagnostics recomputed).

    Raises
    ------
    bayescal.errors.DataError
        If the file is missing or is not a posterior artefact.
    """
    extra = _metadata(path)
    derived = json.loads(extra.attrs.get("derived", "{}"))
    return (*json.loads(extra.attrs["names"]), *derived)


def _metadata(path: str | os.PathLike[str]) -> xr.Dataset:
    """The ``bayescal`` group of a posterior file, its format checked."""
    extra = read_dataset(path, group="bayescal")
    check_format(extra, POSTERIOR_FORMAT, path)
    return extra


def output_noise_from_json(spec: dict[str, Any]) -> OutputNoise:
    """An :class:`OutputNoise` from its JSON form (tuples come back as lists)."""
    fields = dict(spec)
    for key in ("rows", "bases", "prior"):
        fields[key] = tuple(fields[key])
    return OutputNoise(**fields)


def posterior_summary(posterior: Posterior) -> pd.DataFrame:
    """:meth:`Posterior.summary` with a ``unit`` and a ``description`` column."""
    table = posterior.summary()
    attributes = variable_attributes(posterior)
    table["unit"] = [attributes[str(name)][0] for name in table.index]
    table["description"] = [attributes[str(name)][1] for name in table.index]
    return table


def save_posterior_summary(posterior: Posterior, path: str | os.PathLike[str]) -> Path:
    """Write :func:`posterior_summary` as CSV atomically (``posterior-summary.csv``)."""
    return atomic_write_text(path, posterior_summary(posterior).to_csv())
