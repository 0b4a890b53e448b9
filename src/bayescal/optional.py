"""Optional dependencies: is a module there, and what to install when it is not.

bayescal's core needs numpy, scipy, pandas, xarray, ArviZ and matplotlib. A few
features use extras (``pip install "bayescal[hmc]"`` for JAX and BlackJAX,
``[energyplus]``, ``[dask]``, ``[fmu]``); they are imported only where used, and
an absent one is reported by :func:`require` with the install command, never
by a bare ``ImportError``.
"""

from __future__ import annotations

import importlib.util

from bayescal.errors import ConfigError

__all__ = ["install_hint", "module_installed", "require"]

#: Extra of ``pyproject.toml`` that installs each optional module.
EXTRAS = {
    "jax": "hmc",
    "blackjax": "hmc",
    "pyenergyplus": "energyplus",
    "dask": "dask",
    "distributed": "dask",
    "fmpy": "fmu",
    "SALib": "screen",
}


def module_installed(module: str) -> bool:
    """Whether ``module`` can be imported, without importing it."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def install_hint(module: str) -> str:
    """The command that installs ``module`` (through its bayescal extra where it has one)."""
    extra = EXTRAS.get(module)
    return (
        f'install the extra: pip install "bayescal[{extra}]"' if extra else f"pip install {module}"
    )


def require(feature: str, *modules: str) -> None:
    """Raise a one-line :class:`ConfigError` unless every module of ``feature`` is installed.

    Parameters
    ----------
    feature
        What needs the modules, for the message (e.g. ``"sampler 'nuts'"``).
    modules
        Import names of the modules.
    """
    missing = [m for m in modules if not module_installed(m)]
    if missing:
        listed = " and ".join(modules)
        raise ConfigError(
            f"{feature} needs {listed}, which {'is' if len(modules) == 1 else 'are'} not "
            f"installed ({', '.join(missing)} missing)",
            hint=install_hint(missing[0]),
        )
