"""Moved to :mod:`bayescal.config.build` (simulators/ never imports config)."""

# SHIM(issue 14): remove at integration (import from bayescal.config instead)
from bayescal.config.build import build_simulator, nominal_parameters

__all__ = ["build_simulator", "nominal_parameters"]
