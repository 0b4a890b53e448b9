"""Simulators: the built-in finite-volume wall and box, and adapters to external programs."""

from bayescal.simulators.base import Forcing, Simulator

__all__ = ["Forcing", "Simulator"]
