"""`sfr design --simcal` with a calibration's print physics: the run's settings carry them (and a resume keeps
them, refusing another calibration), design.stl is the solid shrunk by the offset and the summary's print is
it grown again."""
import json
from pathlib import Path

import pytest
import trimesh

from labapp.cli.main import main
from labapp.records.simcal import FORMAT, FORWARD_MODEL

TINY = ["--space", "extruded", "--resolution", "16", "--radius", "2"]
PHYSICS = {"anisotropy": 1.3, "offset_mm": 0.2, "swelling_mm": 0.6}


def _simcal(path: Path, physics: dict) -> Path:
    path.write_text(json.dumps({"format": FORMAT, "forward_model": FORWARD_MODEL, "physics": physics,
                                "model": "constant", "seconds_per_mm": 1500.0, "g_per_mm3": 1.3e-3,
                                "resolution": 16, "voxel_size_mm": 1.0, "water_g": 500.0}))
    return path


def test_a_design_for_the_calibrated_print(tmp_path, capsys):
    simcal = _simcal(tmp_path / "simcal.json", PHYSICS)
    out = tmp_path / "design"
    assert main(["design", "--target", "sphere", *TINY, "--max-iter", "40", "--simcal", str(simcal),
                 "--out", str(out)]) == 0
    config = json.loads((out / "config.json").read_text())
    assert (config["anisotropy"], config["print_offset_mm"], config["swelling_mm"]) == (1.3, 0.2, 0.6)
    assert config["physical_correction"] == "none"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["print_physics"] == PHYSICS and "shrunk" in summary["print_files"]["design.stl"]
    assert summary["min_channel_constraint"]["width_mm"] == 0.6
    # the correction stage left no channel narrower than the swelling width: swelling shuts none, and the print,
    # design.stl grown by the offset, is released by the reference evaluator
    assert summary["min_channel_constraint"]["narrow_left_mm3"] == 0
    assert summary["reference"]["method"] == "exact-distance, anisotropy 1.3, surface offset +0.2 mm"
    stl = trimesh.load(out / "design.stl")
    # the file to print is smaller than the print by the offset's shell
    assert stl.volume == pytest.approx(summary["volume_mm3"] - stl.area * 0.2, rel=0.1)
    assert "designed for the print: anisotropy 1.3, offset +0.2 mm" in capsys.readouterr().out
    # a resume with a calibration of other physics is refused
    other = _simcal(tmp_path / "other.json", dict(PHYSICS, swelling_mm=0.3))
    assert main(["design", "--resume", "--simcal", str(other), "--out", str(out)]) == 2
    assert "differs from the run's stored calibration" in capsys.readouterr().err
