"""Problem set-up: domain sizing from the target, mesh targets on the design grid, extrusion height."""
import numpy as np
import pytest

from design.errors import DesignError
from design.forward import simulate
from design.problem import DesignConfig, prepare
from design.targets import target_from_csv


def _long_curve(path, end_mm=15.0, final_mm3=900.0):
    tau = np.linspace(0.0, end_mm, 31)
    path.write_text("tau_mm,released_mm3\n" + "".join(f"{t},{final_mm3 * t / end_mm}\n" for t in tau))
    return path


def test_csv_rising_past_the_horizon_is_refused_with_the_numbers(tmp_path):
    path = _long_curve(tmp_path / "long.csv")
    with pytest.raises(DesignError, match=r"rises until tau = 15 mm.*horizon T = 10 mm.*600 mm\^3 \(66.7%\)"):
        target_from_csv(path, 10.0)
    # a curve that is flat past T loses nothing: accepted
    path.write_text("tau_mm,released_mm3\n0,0\n5,100\n12,100\n")
    assert target_from_csv(path, 10.0).final_mm3 == pytest.approx(100.0)


def test_csv_target_without_a_domain_gets_a_horizon_that_holds_the_whole_curve(tmp_path):
    path = _long_curve(tmp_path / "long.csv")  # releases until 15 mm: the default 20 mm cube has T ~ 10 mm
    problem = prepare(DesignConfig(target=str(path), resolution=16))
    assert problem.target.total_time_mm >= 15.0
    assert problem.target.final_mm3 == pytest.approx(900.0)
    with pytest.raises(DesignError, match="past the design domain's horizon"):
        prepare(DesignConfig(target=str(path), resolution=16, domain_mm=(20.0, 20.0, 20.0)))


@pytest.mark.parametrize("target, space, resolution", [("pill", "extruded", 18), ("sphere", "extruded", 16),
                                                       ("csg", "nfc", 16)])
def test_mesh_target_is_the_source_voxelised_on_the_design_grid(target, space, resolution):
    # odd extrusion heights put the design grid's voxel centres half a voxel off the mesh's own grid
    problem = prepare(DesignConfig(target=target, space=space, resolution=resolution))
    assert problem.source_solid.shape == problem.full_shape
    own = simulate(problem.source_solid.astype(float), problem.dx_mm, total_time_mm=problem.target.total_time_mm,
                   dtau_mm=problem.target.total_time_mm / (problem.target.tau_mm.size - 1)).released_mm3
    np.testing.assert_allclose(problem.target.released_mm3, own, rtol=0, atol=1e-9 * problem.target.final_mm3)
