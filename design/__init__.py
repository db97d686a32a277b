"""The embedded simulator and optimizer (paper sections 3.1-3.6), and the Monte Carlo baseline (section 5.1)."""
from design.errors import DesignError
from design.fabrication.extract import density_mesh, mass_preserving_level
from design.fabrication.ico import IcoConfig, IcoTerm, incremental_compliance
from design.fabrication.printability import assess, overhang_stats, prusa_profile
from design.files.meshio import load_density, load_mesh
from design.files.pipeline import simulate_mesh
from design.files.rundir import DesignResult, run_design
from design.files.targets_io import target_from_csv
from design.forward.concentration import Saturation, release_at_times, release_at_times_vjp, remap_time, remap_time_vjp
from design.forward.simulator import N_MIN, Release, release_gradient, simulate, total_time
from design.geometry.shapes import SAMPLE_SHAPES, sample_shape
from design.geometry.voxelize import voxelize
from design.inverse.config import DesignConfig
from design.inverse.filters import SmoothingFilter, project
from design.inverse.objective import DesignObjective
from design.inverse.presets import PRESET_NAMES, preset_values
from design.inverse.rate import rate_deviation
from design.inverse.spaces import SPACE_CHOICES, build_space
from design.inverse.targets import Target, check_feasibility, constant_acceleration, target_from_mesh
from design.montecarlo.erosion import MonteCarloParams, MonteCarloRelease, simulate_mc
from design.montecarlo.tuning import tune_mc, unit_runs

__all__ = ["DesignConfig", "DesignError", "DesignObjective", "DesignResult", "IcoConfig", "IcoTerm",
           "MonteCarloParams", "MonteCarloRelease", "N_MIN", "PRESET_NAMES", "Release", "SAMPLE_SHAPES",
           "SPACE_CHOICES", "Saturation", "SmoothingFilter", "Target", "assess", "build_space", "check_feasibility",
           "constant_acceleration", "density_mesh", "incremental_compliance", "load_density", "load_mesh",
           "mass_preserving_level", "overhang_stats", "preset_values", "project", "prusa_profile",
           "rate_deviation", "release_at_times", "release_at_times_vjp", "release_gradient",
           "remap_time", "remap_time_vjp", "run_design", "sample_shape", "simulate", "simulate_mc", "simulate_mesh",
           "target_from_csv", "target_from_mesh", "total_time", "tune_mc", "unit_runs", "voxelize"]
