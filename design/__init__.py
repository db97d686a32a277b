"""The embedded simulator and optimizer (paper sections 3.1-3.6)."""
from design.concentration import Saturation, release_at_times, release_at_times_vjp, remap_time, remap_time_vjp
from design.errors import DesignError
from design.forward import N_MIN, Release, release_gradient, simulate, total_time
from design.meshio import load_density, load_mesh
from design.pipeline import simulate_mesh
from design.shapes import SAMPLE_SHAPES, sample_shape
from design.voxelize import voxelize

__all__ = ["DesignError", "N_MIN", "Release", "SAMPLE_SHAPES", "Saturation", "load_density", "load_mesh",
           "release_at_times", "release_at_times_vjp", "release_gradient", "remap_time", "remap_time_vjp",
           "sample_shape", "simulate", "simulate_mesh", "total_time", "voxelize"]
