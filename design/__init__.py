"""The embedded simulator and optimizer (paper sections 3.1-3.6)."""
from design.errors import DesignError
from design.forward import N_MIN, Release, release_gradient, simulate, total_time
from design.meshio import load_density, load_mesh
from design.pipeline import simulate_mesh
from design.shapes import SAMPLE_SHAPES, sample_shape
from design.voxelize import voxelize

__all__ = ["DesignError", "N_MIN", "Release", "SAMPLE_SHAPES", "load_density", "load_mesh", "release_gradient",
           "sample_shape", "simulate", "simulate_mesh", "total_time", "voxelize"]
