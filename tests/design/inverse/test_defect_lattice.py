"""The correction rounds' reference lattice (design.inverse.defect.REFERENCE_PER_VOXEL): one cell per design voxel
for extruded designs, two for the others, and the coarser lattice's bias is the finer one's within 0.1% of the
volume on a print whose release is known."""
import numpy as np
import pytest
import trimesh

import design.inverse.defect as defect
from design.forward.reference import DEFAULT_CELLS, MIN_CELLS, reference_release
from design.inverse.config import DesignConfig
from design.inverse.defect import check_print
from design.inverse.optimize import build_objective
from design.inverse.problem import prepare


@pytest.mark.parametrize("space, per_voxel", [("extruded", 1.0), ("nfc", 2.0)])
def test_rounds_release_the_print_at_the_space_lattice(monkeypatch, space, per_voxel):
    config = DesignConfig(target="sphere", space=space, resolution=24, radius_vox=2.0)
    problem = prepare(config)
    objective = build_objective(problem, config)
    seen = []

    def release(mesh, tau_mm, cells, anisotropy):
        seen.append((cells, float(np.max(mesh.extents))))
        return reference_release(mesh, tau_mm, cells=MIN_CELLS, anisotropy=anisotropy)

    monkeypatch.setattr(defect, "cached_reference_release", release)
    check = check_print(objective, problem, np.full(objective.space.var_shape, 0.9))
    (cells, extent), = seen
    expected = int(np.clip(np.ceil(per_voxel * extent / objective.space.dx_mm), MIN_CELLS, DEFAULT_CELLS))
    assert cells == expected
    assert check.pieces == 1 and np.isfinite(check.fit)


def test_one_cell_per_voxel_finds_the_bias_of_a_cylinder():
    # a cylinder print as an extruded design at resolution 64 makes it (1 cell per voxel: 64 cells across), against
    # its analytic release: side and caps recede together, V(tau) = pi (r - tau)^2 (h - 2 tau) left
    r, h = 5.0, 4.0
    cylinder = trimesh.creation.cylinder(radius=r, height=h, sections=256)
    tau = np.linspace(0.0, 2.0, 41)
    exact = np.pi * (r * r * h - (r - tau) ** 2 * (h - 2.0 * tau))
    coarse = reference_release(cylinder, tau, cells=64).released_mm3
    # the 256-gon holds a little less than the circle: compare in shares of each curve's own volume
    scale = cylinder.volume / (np.pi * r * r * h)
    assert np.abs(coarse - scale * exact).max() < 1e-3 * cylinder.volume
