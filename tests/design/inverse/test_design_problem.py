"""Problem set-up: domain sizing from the target, mesh targets on the design grid, extrusion height."""
import numpy as np
import pytest
import trimesh
from scipy import ndimage

from design.errors import DesignError
from design.files.targets_io import load_problem, target_from_csv
from design.forward.reference import design_lattice, reference_release
from design.forward.simulator import simulate
from design.geometry.shapes import sample_shape
from design.inverse.config import DesignConfig
from design.inverse.problem import prepare
from design.inverse.settings import DEFAULT_RADIUS_MM
from design.inverse.starts import START_FILL


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
    problem = load_problem(DesignConfig(target=str(path), resolution=16))
    assert problem.target.total_time_mm >= 15.0
    assert problem.target.final_mm3 == pytest.approx(900.0)
    with pytest.raises(DesignError, match="past the design domain's horizon"):
        load_problem(DesignConfig(target=str(path), resolution=16, domain_mm=(20.0, 20.0, 20.0)))


@pytest.mark.parametrize("target, space, resolution", [("pill", "extruded", 18), ("sphere", "extruded", 16),
                                                       ("csg", "nfc", 16)])
def test_mesh_target_is_the_source_s_physical_release_whatever_the_design_grid(target, space, resolution):
    # odd extrusion heights put the design grid's voxel centres half a voxel off the mesh's own grid: the
    # target does not move with them; the recovery check's voxelised source still lives on the design grid
    problem = prepare(DesignConfig(target=target, space=space, resolution=resolution))
    assert problem.source_solid.shape == problem.full_shape
    mesh = sample_shape(target)
    reference = reference_release(mesh, problem.target.tau_mm, cells=design_lattice(resolution))
    np.testing.assert_array_equal(problem.target.released_mm3, reference.released_mm3)
    assert problem.target_error_mm3 == reference.error_mm3
    assert problem.target.released_mm3[0] == 0.0
    assert problem.target.final_mm3 == pytest.approx(mesh.volume, rel=1e-9)
    # the design grid's own release of the source differs from it by its first-order error
    grid = simulate(problem.source_solid.astype(float), problem.dx_mm, total_time_mm=problem.target.total_time_mm,
                    dtau_mm=problem.target.total_time_mm / (problem.target.tau_mm.size - 1)).released_mm3
    assert np.abs(grid - problem.target.released_mm3).max() > 10 * problem.target_error_mm3


def _start_mm3(problem):
    """Volume the start region covers over the extrusion height (all mirror copies), mm^3."""
    space = problem.space
    height_mm = space.grid_shape[2] * problem.dx_mm
    return np.count_nonzero(problem.start_region) * problem.dx_mm ** 2 * height_mm * space.multiplicity


def test_extruded_analytic_target_gets_a_compact_height_and_start():
    problem = prepare(DesignConfig(target="zero-order:final=0.15,duration=0.2", space="extruded", resolution=24))
    target, space, dx = problem.target, problem.space, problem.dx_mm
    height_mm = space.grid_shape[2] * dx
    end_mm = 0.2 * 10.0 - 0.5 * dx  # duration 0.2 of the 20 mm cube's horizon
    # as tall as a cube of the target's volume, and at least twice the release's duration
    assert height_mm == pytest.approx(max(target.final_mm3 ** (1 / 3), 2 * end_mm + 2 * dx), abs=dx)
    assert target.total_time_mm >= 0.2 * 9.0 and target.final_mm3 == pytest.approx(0.15 * 20.0 ** 3, rel=0.02)
    region = problem.start_region
    assert region is not None and region.shape == space.var_shape
    # a centred square that holds the target's volume at START_FILL: no room for a hole (whole cells of
    # 0.83 mm on a side of about 10 mm: the area is within about 20%)
    assert region[0, 0] and np.array_equal(region, np.logical_and.outer(region[:, 0], region[0]))
    assert _start_mm3(problem) * START_FILL == pytest.approx(target.final_mm3, rel=0.2)


def test_extruded_mesh_start_covers_the_source_footprint_and_nfc_starts_everywhere():
    problem = prepare(DesignConfig(target="pill", space="extruded", resolution=24))
    region = problem.start_region
    outline = problem.source_solid[problem.full_shape[0] // 2:, problem.full_shape[1] // 2:].any(axis=2)
    # the outline's rim is in the start (the core may be left out)
    rim = outline & ~np.pad(outline[1:, 1:], ((0, 1), (0, 1)))
    assert np.all(region[rim]) and not region.all()
    assert prepare(DesignConfig(target="pill", space="nfc", resolution=16)).start_region is None


def _write(mesh, path):
    mesh.export(path)
    return str(path)


def test_extruded_start_leaves_out_the_core_a_ring_releases_too_late_from(tmp_path):
    # a ring 6 mm tall whose wall is 3 mm thick ends its release at 1.5 mm, long before its faces
    # (3 mm) would dissolve a solid core: the start's core is empty
    ring = _write(trimesh.creation.annulus(r_min=4.0, r_max=7.0, height=6.0, sections=64), tmp_path / "ring.stl")
    problem = load_problem(DesignConfig(target=ring, space="extruded", resolution=32))
    region = problem.start_region
    assert region is not None and not region[0, 0] and region[0].any()
    assert _start_mm3(problem) * START_FILL >= problem.target.final_mm3 * (1 - 1e-9)
    # a flat tablet's faces dissolve it before any in-plane core matters: its whole footprint starts
    tablet = _write(trimesh.creation.box(extents=(14.0, 10.0, 3.0)), tmp_path / "tablet.stl")
    region = load_problem(DesignConfig(target=tablet, space="extruded", resolution=32)).start_region
    assert region is not None and np.array_equal(region, np.logical_and.outer(region[:, 0], region[0]))


def test_radius_in_mm_gives_the_same_feature_size_at_every_resolution():
    for resolution in (16, 32):
        problem = prepare(DesignConfig(target="sphere", resolution=resolution, radius_mm=2.0))
        assert problem.radius_vox * problem.dx_mm == pytest.approx(2.0)
    assert prepare(DesignConfig(target="sphere", resolution=16, radius_vox=3.0)).radius_vox == 3.0
    with pytest.raises(DesignError, match="not both"):
        DesignConfig(target="sphere", radius_vox=3.0, radius_mm=1.0)


@pytest.mark.parametrize("field, value", [("w_connect", -1.0), ("connect_tail", -0.1)])
def test_connectivity_settings_must_not_be_negative(field, value):
    with pytest.raises(DesignError, match=f"{field} must be >= 0"):
        DesignConfig(target="sphere", **{field: value})


def test_a_source_in_separate_pieces_is_warned_about_unless_pieces_are_allowed(two_boxes_stl, caplog):
    path = two_boxes_stl
    with caplog.at_level("WARNING", logger="design.inverse.problem"):
        problem = load_problem(DesignConfig(target=str(path), resolution=16))
    assert len(problem.warnings) == 1 and "the source is 2 separate pieces" in problem.warnings[0]
    assert problem.warnings[0] in caplog.text
    assert load_problem(DesignConfig(target=str(path), resolution=16, allow_pieces=True)).warnings == ()
    assert prepare(DesignConfig(target="sphere", resolution=16)).warnings == ()


def test_a_rate_fitted_target_too_short_for_the_grid_is_warned_about():
    """A zero-order target of final 0.1 and duration 0.12 releases its middle 80% over ~0.95 mm of tau: about six
    voxels at resolution 128 (dx 0.156 mm) and twelve at 256, against `RATE_SPAN_MIN_VOX` = 10."""
    target = "zero-order:final=0.1,duration=0.12"
    coarse = prepare(DesignConfig(target=target, resolution=128)).warnings
    assert len(coarse) == 1 and "spans 6.1 voxels of tau at resolution 128" in coarse[0]
    needed = int(coarse[0].rsplit("at about resolution ", 1)[1].split()[0])
    assert 200 <= needed <= 220 and prepare(DesignConfig(target=target, resolution=needed)).warnings == ()
    assert prepare(DesignConfig(target=target, resolution=128, w_rate=0.0)).warnings == ()  # the rate is not fitted
    assert prepare(DesignConfig(target="zero-order:final=0.1,duration=0.5", resolution=64)).warnings == ()


def test_a_file_target_needs_its_contents(tmp_path):
    with pytest.raises(DesignError, match="is a mesh file: load it with design.files.targets_io.load_problem"):
        prepare(DesignConfig(target=str(tmp_path / "part.stl"), resolution=16))
    with pytest.raises(DesignError, match="is a CSV file: read it with design.files.targets_io.load_problem"):
        prepare(DesignConfig(target=str(tmp_path / "curve.csv"), resolution=16))
    with pytest.raises(DesignError, match="target mesh .*part.stl does not exist"):
        load_problem(DesignConfig(target=str(tmp_path / "part.stl"), resolution=16))


def _wafer_curve(path, end_mm, final_mm3):
    """A flat print's release: steady, then stopping at ``end_mm`` (a disc 18 mm across, both faces)."""
    tau = np.linspace(0.0, 4.0, 81)
    remaining = np.pi * np.clip(9.0 - tau, 0.0, None) ** 2 * np.clip(2.0 * end_mm - 2.0 * tau, 0.0, None)
    released = final_mm3 * (1.0 - remaining / remaining[0])
    path.write_text("tau_mm,released_mm3\n" + "".join(f"{t},{c}\n" for t, c in zip(tau, released)))
    return str(path)


def test_a_fast_curve_starts_from_a_square_a_cross_and_a_ring_that_hold_its_volume(tmp_path):
    # a wafer's curve (850 mm^3, release ending at 2 mm) through a prism 10 mm tall: a solid square of its
    # volume keeps a core 4.6 mm from its edge; the cross and the ring hold the volume within about the end of
    # an edge, each in one piece (docs/design.md#extruded-start)
    end_mm, final_mm3 = 2.0, 850.0
    config = DesignConfig(target=_wafer_curve(tmp_path / "wafer.csv", end_mm, final_mm3), space="extruded",
                          resolution=40, domain_mm=(24.0, 24.0, 12.0), height_mm=10.0)
    problem = load_problem(config)
    assert config.starts == len(problem.start_regions) == 3
    dx, space = problem.dx_mm, problem.space
    height_mm = space.grid_shape[2] * dx
    square, cross, ring = (space.unfold(r) for r in problem.start_regions)  # the whole footprint
    for outline in (square, cross, ring):
        held = np.count_nonzero(outline) * dx ** 2 * height_mm * START_FILL
        assert held == pytest.approx(problem.target.final_mm3, rel=0.15)  # whole cells of 0.6 mm
        assert ndimage.label(outline)[1] == 1
    depth = [ndimage.distance_transform_edt(np.pad(o, 1)) * dx for o in (square, cross, ring)]
    assert depth[0].max() > 2.0 * end_mm  # the square's core releases late
    assert depth[1].max() <= np.sqrt(2.0) * (end_mm + dx)  # the cross's crossing, its deepest point
    assert depth[2].max() <= end_mm + dx
    hole = ~ring & (ndimage.binary_fill_holes(ring))
    assert hole[ring.shape[0] // 2 - 1:ring.shape[0] // 2 + 1, ring.shape[1] // 2 - 1:ring.shape[1] // 2 + 1].all()
    assert np.sqrt(np.count_nonzero(hole) / np.pi) * dx >= DEFAULT_RADIUS_MM  # at least the smoothing radius
    # a smaller volume leaves a solid square's core within the end: the square alone
    small = DesignConfig(target=_wafer_curve(tmp_path / "small.csv", end_mm, 150.0), space="extruded",
                         resolution=40, domain_mm=(24.0, 24.0, 12.0), height_mm=10.0)
    assert len(load_problem(small).start_regions) == 1
