"""calibrate-sim releases the set's meshes on several threads: each release is the one a single thread makes."""
from pathlib import Path

import numpy as np
import trimesh

from labapp.jobs import calibrate_sim, printrelease
from labapp.records.simcalset import SetRow

MESHES = {"bar.stl": trimesh.creation.box((11.0, 3.0, 3.0)), "slab.stl": trimesh.creation.box((8.0, 8.0, 2.0)),
          "rod.stl": trimesh.creation.cylinder(radius=2.0, height=9.0, sections=24)}
PHYSICS = {"anisotropy": 0.75, "offset_mm": 0.1, "swelling_mm": 0.0}


def _sims(monkeypatch, workers: int):
    monkeypatch.setattr(calibrate_sim, "ROW_WORKERS", workers)
    monkeypatch.setattr(printrelease, "_REFERENCE_CACHE", {})
    monkeypatch.setattr(printrelease, "_BIAS_CACHE", {})
    rows = [SetRow(i + 1, Path(f"run{i}"), Path(name), 1.0) for i, name in enumerate(MESHES)]
    rows.append(SetRow(len(rows) + 1, Path("again"), Path("bar.stl"), 1.0))   # a mesh listed twice: released once
    return calibrate_sim._Simulations(rows, {Path(n): m for n, m in MESHES.items()}, resolution=8)


def test_rows_released_on_threads_are_the_rows_released_one_by_one(monkeypatch):
    alone = _sims(monkeypatch, 1)
    serial = [alone.simulation(row, PHYSICS) for row in alone.rows]
    threaded = _sims(monkeypatch, 3)
    threaded.simulate_rows(PHYSICS)
    assert len(threaded.simulated) == len(MESHES)
    for row, (tau, vol, dx) in zip(threaded.rows, serial):
        t_tau, t_vol, t_dx = threaded.simulated[(row.mesh, *PHYSICS.values())]
        assert np.array_equal(t_tau, tau) and np.array_equal(t_vol, vol) and t_dx == dx
