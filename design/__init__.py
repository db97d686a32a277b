"""The embedded simulator and optimizer (paper sections 3.1-3.6)."""
from design.errors import DesignError
from design.forward import Release, release_gradient, simulate, total_time

__all__ = ["DesignError", "Release", "release_gradient", "simulate", "total_time"]
