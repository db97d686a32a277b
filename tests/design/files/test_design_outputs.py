"""The printed solid's release on a grid finer than the design's, and the result lines of a summary."""
import numpy as np
import trimesh

from design.fabrication.extract import revoxelize
from design.files.printed import fine_release, solid_release
from design.files.summary_text import percent_text, print_fit_text, summary_lines
from design.inverse.objective import rel_rmse


def test_fine_release_of_a_turned_plate_is_closer_to_its_exact_release():
    """The printed mesh on voxels half the design's size: a 6 x 5 x 1.3 mm plate turned by 17 degrees
    on a 0.25 mm grid has the exact release abc - (a - 2t)(b - 2t)(c - 2t) (uniform inward motion).
    The design grid misses it by ~15% RMS (the 1.3 mm side is five voxels); halving the voxel must cut
    that error by more than half (voxel volume errors fall with dx), and it measures ~2.6%."""
    a, b, c = 6.0, 5.0, 1.3
    mesh = trimesh.creation.box(extents=(a, b, c))
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.radians(17.0), (0.0, 0.0, 1.0)))
    mesh.apply_translation((5.0, 5.0, 5.0))
    dx, shape, origin, mirror = 0.25, (40, 40, 40), np.zeros(3), (True, True, True)
    tau = np.linspace(0.0, 1.0, 1001)
    exact = a * b * c - np.prod([np.clip(s - 2.0 * tau, 0.0, None) for s in (a, b, c)], axis=0)
    design_grid = solid_release(revoxelize(mesh, dx, origin, shape), dx, mirror, 1.0, 1e-3)
    fine = fine_release(mesh, dx, origin, shape, mirror, 1.0, 1e-3, 2)
    assert rel_rmse(fine, exact) < 0.5 * rel_rmse(design_grid, exact)
    assert rel_rmse(fine, exact) < 0.04


def test_fine_release_without_a_solid_is_zero():
    assert not np.any(fine_release(None, 0.5, np.zeros(3), (8, 8, 8), (True, True, True), 2.0, 0.01, 2))


def test_a_summary_fraction_prints_as_a_percentage_or_a_dash():
    assert percent_text(0.012345) == "1.23%" and percent_text(0.012345, 3) == "1.234%"
    assert percent_text(0.5, 0) == "50%" and percent_text(None) == "-"


def test_summary_lines_read_the_summary(tmp_path):
    (tmp_path / "design.stl").write_text("solid\n")
    (tmp_path / "summary.json").write_text("{}")
    summary = {"status": "max_iter", "iterations": 40, "seconds": 12.34, "seconds_per_iteration": 0.3085,
               "rel_rmse_print": 0.00412, "rel_rmse_print_error": 0.0005, "rel_rmse_density": 0.01234,
               "rel_rmse_design_grid_binary": 0.02,
               "rate_dev_mid80": {"print": 0.1, "density": 0.05, "design_grid_binary": None}, "pieces": 1,
               "print_mass_g": 1.75,
               "min_channel_mm": 1.5, "enclosed_voids": 0, "enclosed_void_mm3": 0.0, "overhang_fraction": 0.125,
               "max_overhang_run_mm": 2.0, "preset": "paper:pill", "ico": {"J_fab": 0.5, "layers": 8, "fab_time_share": 0.25},
               "simcal": {"model": "lag", "seconds_per_mm": 600.0}, "rel_rmse_physical": 0.05, "warnings": ["thin"]}
    assert summary_lines(summary, tmp_path) == [
        "max_iter after 40 evaluations (12.3 s, 0.308 s each)",
        "fit of the print: rel. RMSE 0.412% (+/- 0.050%) (design.stl by exact surface distances, against the "
        "target's physical release)",
        "design grid (diagnostics): rel. RMSE density 1.234%, binary solid 2.000%",
        "rate deviation, middle 80% of the release: print 10.00%; design grid: density 5.00%, binary solid -",
        "pieces 1, print mass 1.750 g, narrowest channel 1.50 mm, no enclosed voids",
        "overhangs along +z: 12.5% of the solid, longest run 2.00 mm; preset paper:pill",
        "ICO J_fab 0.5 of the start design's, 8 layers, 25% of the time",
        "physical prediction (lag model, 600.0 s/mm): rel. RMSE 5.000% of the target's final grams (curves_physical.csv)",
        "warning: thin",
        f"results in {tmp_path}: design.stl, summary.json"]


def test_a_print_fit_not_computed_reads_as_a_dash():
    assert print_fit_text({"rel_rmse_print": None}) == "-"  # no solid extracted, or a summary from before
    assert print_fit_text({"rel_rmse_print": 0.01, "rel_rmse_print_error": None}) == "1.000%"
