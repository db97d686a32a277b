"""Print mass, narrowest channel, enclosed voids and slicer profile."""
import numpy as np
import pytest

from design.errors import DesignError
from design.fabrication.printability import (
    assess,
    enclosed_voids,
    narrowest_channel_mm,
    overhang_stats,
    overhangs,
    print_mass_g,
    prusa_profile,
)
from design.files.summary_text import enclosed_voids_text


def _hollow_ball(hole_vox: int, n: int = 40) -> np.ndarray:
    z, y, x = np.mgrid[:n, :n, :n] - n / 2 + 0.5
    r = np.sqrt(x ** 2 + y ** 2 + z ** 2)
    solid = (r < 18) & (r > 8)
    # a square hole hole_vox voxels wide from the cavity to the outside along +z
    solid[(np.abs(x) < hole_vox / 2) & (np.abs(y) < hole_vox / 2) & (z > 0)] = False
    return solid


def test_print_mass_uses_paper_density():
    # 1000 mm^3 = 1 cm^3 at 1.32 g/cm^3
    assert print_mass_g(1000.0) == pytest.approx(1.32)


@pytest.mark.parametrize("hole_vox", [2, 4, 6])
def test_channel_into_a_cavity_is_measured_within_half_a_voxel(hole_vox):
    dx = 0.1
    width = narrowest_channel_mm(_hollow_ball(hole_vox), dx, 2.0)
    assert width == pytest.approx(hole_vox * dx, abs=0.5 * dx + 1e-9)


def test_solid_ball_and_sealed_cavity_have_no_open_channel():
    z, y, x = np.mgrid[:30, :30, :30] - 14.5
    r = np.sqrt(x ** 2 + y ** 2 + z ** 2)
    assert narrowest_channel_mm(r < 12, 0.1, 2.0) is None
    assert narrowest_channel_mm((r < 12) & (r > 5), 0.1, 2.0) is None


def test_enclosed_voids_are_counted_and_measured():
    z, y, x = np.mgrid[:30, :30, :30] - 14.5
    r = np.sqrt(x ** 2 + y ** 2 + z ** 2)
    shell = (r < 12) & (r > 5)
    cavity = int(np.count_nonzero(r <= 5))
    assert enclosed_voids(r < 12) == (0, 0)
    assert enclosed_voids(shell) == (1, cavity)
    # a second cavity, and a hole that opens the first: one left
    small = (np.abs(x - 8.5) <= 1) & (np.abs(y) <= 1) & (np.abs(z) <= 1)  # inside the shell's wall
    two = shell & ~small
    assert enclosed_voids(two) == (2, cavity + int(np.count_nonzero(small)))
    opened = two & ~((np.abs(x) < 2) & (np.abs(y) < 2) & (z > 0))
    assert enclosed_voids(opened) == (1, int(np.count_nonzero(small)))
    # void on the grid's border is open medium, even where the solid touches the border elsewhere
    slab = np.zeros((10, 10, 10), bool)
    slab[:, :, 3:7] = True
    assert enclosed_voids(slab) == (0, 0)


def test_assess_reports_and_warns_of_enclosed_voids():
    z, y, x = np.mgrid[:30, :30, :30] - 14.5
    r = np.sqrt(x ** 2 + y ** 2 + z ** 2)
    report = assess((r < 12) & (r > 5), 0.1)
    assert report.enclosed_voids == 1
    assert report.enclosed_void_mm3 == pytest.approx(np.count_nonzero(r <= 5) * 1e-3)
    assert any("encloses 1 void" in w and "trap air" in w for w in report.warnings)
    assert assess(_hollow_ball(4), 0.1).enclosed_voids == 0


def test_assess_warns_below_threshold():
    report = assess(_hollow_ball(4), 0.1, warn_channel_mm=1.0)
    assert report.min_channel_mm < 1.0 and "clog" in report.warnings[0]
    assert report.mass_g == pytest.approx(report.volume_mm3 * 1.32e-3)
    assert assess(_hollow_ball(4), 0.1, warn_channel_mm=0.2).warnings == ()
    with pytest.raises(DesignError, match="warning width"):
        assess(_hollow_ball(4), 0.1, warn_channel_mm=0.0)


def test_prusa_profile_has_the_paper_settings():
    text = prusa_profile()
    settings = dict(line.split(" = ") for line in text.splitlines() if not line.startswith("#"))
    assert settings["layer_height"] == "0.1" and settings["extrusion_width"] == "0.2"
    assert settings["fill_density"] == "100%" and settings["fill_pattern"] == "concentric"
    assert settings["temperature"] == "245" and settings["bed_temperature"] == "85"


def test_overhangs_of_hand_built_solids():
    solid = np.zeros((7, 5, 6), dtype=bool)
    solid[3, 2, :4] = True  # a post standing on the plate
    solid[:, 2, 4] = True  # a 7-voxel beam across its top: 4 of its voxels reach past the post's neighbours
    over = overhangs(solid)
    assert sorted(np.argwhere(over)[:, 0].tolist()) == [0, 1, 5, 6] and over[:, :, :4].sum() == 0
    fraction, run_mm = overhang_stats(solid, 0.5)
    assert fraction == pytest.approx(4 / 11) and run_mm == pytest.approx(2 * 0.5)
    stairs = np.zeros((6, 3, 6), dtype=bool)
    for k in range(6):
        stairs[k, 1, k] = True  # 45 degrees: each voxel rests on its side neighbour below
    assert overhang_stats(stairs, 1.0) == (0.0, 0.0)
    roof = np.zeros((6, 6, 5), dtype=bool)
    roof[:, :, 3] = True  # a slab lifted off the grid's floor rests on the plate as printed
    assert overhang_stats(roof, 0.25) == (0.0, 0.0)
    roof[0, 0, 1:3] = True  # on a corner post: all but the post's top and its two side neighbours overhang
    assert overhang_stats(roof, 0.25) == (pytest.approx(33 / 38), pytest.approx(1.5))
    assert overhang_stats(np.zeros((2, 2, 2), bool), 1.0) == (0.0, 0.0)
    with pytest.raises(DesignError, match="3D solid"):
        overhangs(np.zeros((3, 3), bool))


def test_supports_follow_the_design_space():
    on = dict(line.split(" = ") for line in prusa_profile(supports=True).splitlines() if not line.startswith("#"))
    off = dict(line.split(" = ") for line in prusa_profile().splitlines() if not line.startswith("#"))
    assert on["support_material"] == "1" and off["support_material"] == "0"


def test_enclosed_voids_phrase_reads_the_summary():
    assert enclosed_voids_text({"enclosed_voids": 0, "enclosed_void_mm3": 0.0}) == "no enclosed voids"
    assert enclosed_voids_text({"enclosed_voids": 2, "enclosed_void_mm3": 12.5}) == "2 enclosed voids, 12.5 mm^3"
    assert enclosed_voids_text({"pieces": 1}) == "enclosed voids not assessed"
