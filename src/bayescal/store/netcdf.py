"""What the netCDF artefacts share: the engine, reading, the format check, attributes.

Every netCDF artefact (``emulator.nc``, ``posterior.nc``, ``discrepancy.nc``)
is HDF5 through ``h5netcdf``, carries a ``format`` attribute naming its kind
and version (``"bayescal-emulator/1"``) and is written atomically through
:func:`bayescal.atomic.atomic_write_path`. Variables with a physical meaning
carry ``units`` (as the study file or :mod:`bayescal.glossary` writes them;
``"1"`` for dimensionless numbers) and ``description`` attributes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Final

import numpy as np
import xarray as xr

from bayescal.atomic import atomic_write_path
from bayescal.emulator.assemble import OutputStack
from bayescal.emulator.basis import Standardisation
from bayescal.errors import DataError
from bayescal.glossary import GLOSSARY

__all__ = [
    "DIMENSIONLESS",
    "ENGINE",
    "check_format",
    "describe_variables",
    "output_unit",
    "read_dataset",
    "read_output_stack",
    "write_dataset",
]

ENGINE: Final = "h5netcdf"
#: The ``units`` of a dimensionless number (CF conventions).
DIMENSIONLESS: Final = "1"


def output_unit(name: str) -> str:
    """The unit of a glossary series (``"W/m²"``), ``""`` for a name outside the glossary."""
    quantity = GLOSSARY.get(name)
    return quantity.unit if quantity is not None else ""


def describe_variables(
    ds: xr.Dataset, attrs: Mapping[str, tuple[str, str]], *, long_names: bool = False
) -> xr.Dataset:
    """Set ``units`` and ``description`` (and ``long_name``) on the variables of ``ds``.

    Parameters
    ----------
    ds
        The dataset; changed in place and returned.
    attrs
        Variable name -> ``(units, description)``; an empty unit is left out,
        names not in ``ds`` are skipped.
    long_names
        Also set ``long_name`` to the description (what plotting tools label
        axes with).
    """
    for name, (units, description) in attrs.items():
        if name not in ds.variables:
            continue
        target = ds[name].attrs
        if units:
            target["units"] = units
        if description:
            target["description"] = description
            if long_names:
                target["long_name"] = description
    return ds


def write_dataset(ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write ``ds`` to netCDF (HDF5, ``h5netcdf``) atomically; returns the final path."""

    def write(temp: Path) -> None:
        ds.to_netcdf(os.fspath(temp), engine=ENGINE)

    return atomic_write_path(path, write)


def read_dataset(path: str | os.PathLike[str], group: str | None = None) -> xr.Dataset:
    """Read a netCDF artefact (or one group of it) into memory.

    Raises
    ------
    bayescal.errors.DataError
        If the file is missing or cannot be read as netCDF (or lacks ``group``).
    """
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


def check_format(ds: xr.Dataset, expected: str, path: str | os.PathLike[str]) -> None:
    """Refuse a dataset whose ``format`` attribute is not ``expected``.

    Raises
    ------
    bayescal.errors.DataError
        Naming the format found and the one expected.
    """
    found = ds.attrs.get("format")
    if found != expected:
        raise DataError(
            f"{os.fspath(path)}: expected a {expected!r} artefact, found format {found!r}",
            hint="re-run the stage that writes it",
        )


def read_output_stack(ds: xr.Dataset) -> OutputStack:
    """The output standardisation of an artefact (``output_names``/``output_sizes``
    attributes, ``std_mean`` and ``std_sd`` variables)."""
    names = json.loads(ds.attrs["output_names"])
    sizes = json.loads(ds.attrs["output_sizes"])
    bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    mean, sd = ds["std_mean"].values, ds["std_sd"].values
    stds = tuple(
        Standardisation(mean[bounds[q] : bounds[q + 1]], sd[bounds[q] : bounds[q + 1]])
        for q in range(len(names))
    )
    return OutputStack(tuple(names), stds)
