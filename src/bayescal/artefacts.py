"""Moved to :mod:`bayescal.store` (issue 14); this module only re-exports.

SHIM(issue 14): remove at integration (import from bayescal.store.emulator and
bayescal.store.posterior instead).
"""

from bayescal.store.emulator import load_emulator, save_emulator  # SHIM(issue 14)
from bayescal.store.posterior import load_posterior, save_posterior  # SHIM(issue 14)

__all__ = ["load_emulator", "load_posterior", "save_emulator", "save_posterior"]
