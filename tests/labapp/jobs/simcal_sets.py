"""Synthetic calibration sets for the calibrate-sim tests: each run a curve CSV (time, concentration in the bath,
released grams) and its mesh as STL, listed in a set file."""
from pathlib import Path

import numpy as np


def write_run(folder: Path, name: str, mesh, t_s: np.ndarray, released_g: np.ndarray, mass_g: float,
              water_g: float = 500.0, fmt: str = "%.9f") -> str:
    """Write ``NAME.csv`` (concentration = released / water, g/kg) and ``NAME.stl``; returns the set file's row
    (run, mesh, weighed mass, water)."""
    conc = np.asarray(released_g) / (water_g / 1000.0)
    np.savetxt(folder / f"{name}.csv", np.column_stack([t_s, conc, conc, released_g]), delimiter=",", comments="",
               header="t_s,conc_g_per_kg,conc_smooth_g_per_kg,released_g", fmt=fmt)
    mesh.export(folder / f"{name}.stl")
    return f"{name}.csv,{name}.stl,{mass_g:.9f},{water_g}"


def write_set(folder: Path, rows: list[str]) -> Path:
    """The set file ``set.csv`` listing the rows of :func:`write_run`."""
    (folder / "set.csv").write_text("\n".join(["run,mesh,object_mass_g,water_g", *rows]) + "\n")
    return folder / "set.csv"
