"""Two-material design: the objective's gradient, its slowness law against the forward model, the targets' phases and
feasibility, the printable pair, the two-object 3MF and a small run end to end."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from design.errors import DesignError
from design.fabrication.twomaterial_print import printable_pair, thicken_walls, thinnest_wall_mm
from design.files import twomaterial_outputs
from design.files.threemf import read_objects, write_objects
from design.files.twomaterial_run import run_two_material
from design.forward.twomaterial import simulate_two
from design.inverse.twomaterial_objective import TwoMaterialObjective, composite_release, composite_slowness
from design.inverse.twomaterial_problem import TwoMaterialSettings, prepare_two, start_layout
from design.inverse.twomaterial_targets import parse_two_material, target_phases

DELAY = "delay-zero:delay=2,rate=10,volume=20"
PULSES = "pulses:volume=8,width=1.25,gap=2"


def _objective(spec: str, s: float, space: str) -> TwoMaterialObjective:
    p = prepare_two(TwoMaterialSettings(spec, s, space=space, resolution=16))
    return TwoMaterialObjective(p.space, p.target.released_mm3, p.target.total_time_mm, radius_vox=1.5,
                                slowness=p.slowness, beta=4.0, w_binary=0.02)


@pytest.mark.parametrize("spec,s,space", [(DELAY, 0.25, "nfc"), (PULSES, 0.25, "extruded"),
                                          ("constant:rate=4,volume=16", 0.0, "nfc")])
def test_gradient_matches_central_differences(spec, s, space):
    # smooth random fields in (0.2, 0.8); central differences with step 1e-6 along a random direction. The
    # truncation is O(1e-12) and the round-off ~1e-16 J / 1e-6; the marcher's upwind choices are locally constant
    obj = _objective(spec, s, space)
    rng = np.random.default_rng(3)
    x = 0.2 + 0.6 * rng.random(obj.x_shape)
    _, grad, _, _ = obj.evaluate(x)
    for _ in range(2):
        d = rng.standard_normal(x.shape)
        h = 1e-6
        fd = (obj.evaluate(x + h * d)[0] - obj.evaluate(x - h * d)[0]) / (2 * h)
        assert abs(fd - np.sum(grad * d)) <= 1e-5 * np.sum(np.abs(grad * d))


def test_binary_fields_release_as_the_forward_model():
    # for phi, f in {0, 1} the RAMP law is the forward model's linear law: the same curve to round-off
    rng = np.random.default_rng(0)
    phi = (rng.random((9, 10, 11)) < 0.7).astype(float)
    f = (rng.random(phi.shape) < 0.5).astype(float)
    s = 0.5
    n, _, _ = composite_slowness(phi, f, 1.0 / s)
    mine = composite_release(n, phi * f, 0.1, (False,) * 3, 3.0, 301)
    ref = simulate_two(phi * f, phi * (1 - f), 0.1, s, total_time_mm=3.0, dtau_mm=0.01)
    assert np.max(np.abs(mine.released_mm3 - ref.released_mm3)) < 1e-12


def test_grey_barrier_is_crossed_faster_than_its_share():
    n, _, _ = composite_slowness(np.ones(1), np.array([0.9]), 50.0)
    assert n[0] < 1.0 + 49.0 * 0.1 / 2      # RAMP q = 3: w(0.1) = 0.027, the linear law 0.1


def test_phases_of_the_pulses():
    p = prepare_two(TwoMaterialSettings(PULSES, 0.25, resolution=16))
    (a, b), = p.phases.pauses
    assert abs(a - 1.25) < 0.1 and abs(b - 3.25) < 0.1
    assert [round(v) for _, _, v in p.phases.releases] == [8, 8]
    assert any("layer at least 0.50" in n for n in p.needs)


@pytest.mark.parametrize("spec,s,match", [
    (DELAY, 0.0, "delay 2.* insoluble barrier"),
    (PULSES, 0.0, "pause .* insoluble barrier"),
    ("delay-zero:delay=40,rate=10,volume=20", 0.25, "domain.*--domain-mm"),
    ("delay-zero:delay=2,rate=10", 0.25, "needs volume"),
    ("pulses:volume=8,width=-1,gap=2", 0.25, "width = -1"),
    ("constant:rate=4,volume=16,speed=3", 0.0, "unknown parameter 'speed'"),
])
def test_targets_the_barrier_cannot_give_are_refused_naming_the_field(spec, s, match):
    with pytest.raises(DesignError, match=match):
        prepare_two(TwoMaterialSettings(spec, s, resolution=16, domain_mm=20.0 if "delay=40" in spec else None))


def test_settings_are_checked_naming_the_field():
    with pytest.raises(DesignError, match="space = 'ico'.*stiffness"):
        TwoMaterialSettings(DELAY, 0.25, space="ico")
    with pytest.raises(DesignError, match="barrier_speed"):
        TwoMaterialSettings(DELAY, -1.0)
    assert parse_two_material("constant:rate=4,volume=16") == ("constant", {"rate": 4.0, "volume": 16.0})


def test_a_thin_wall_in_front_of_covered_drug_is_thickened():
    drug = np.zeros((12, 12, 12), bool)
    drug[3:9, 3:9, 3:9] = True
    barrier = np.zeros_like(drug)
    barrier[2:10, 2:10, 2:10] = True
    barrier &= ~drug                                    # a one-voxel shell: 0.25 mm, under the 0.4 mm minimum
    assert thinnest_wall_mm(drug, barrier, 0.25) == pytest.approx(0.25)
    d2, b2, changed = thicken_walls(drug, barrier, 0.25, 0.4)
    assert changed == 6 ** 3 - 4 ** 3 and thinnest_wall_mm(d2, b2, 0.25) == pytest.approx(0.5)
    assert not (d2 & b2).any()


def test_drug_open_to_the_bath_is_not_thickened_and_pieces_are_counted():
    phi = np.zeros((10, 10, 10))
    f = np.zeros_like(phi)
    phi[2:8, 2:8, 2:8] = 1.0
    f[4:6, 4:6, 2:8] = 1.0                               # a drug column open at both ends in a 2-voxel wall
    pair = printable_pair(phi, f, 0.2, 0.4)
    assert pair.thickened_voxels == 0 and pair.pieces == {"print": 1, "drug": 1, "barrier": 1}
    assert pair.min_barrier_mm is None and pair.thin_barrier_mm3 == 0.0    # reached through its ends; walls 0.4 mm


def test_3mf_round_trips_two_separate_objects(tmp_path):
    a = trimesh.creation.box((1, 1, 1))
    b = trimesh.creation.box((2, 2, 2))
    b.apply_translation((3, 0, 0))
    write_objects(tmp_path / "x.3mf", {"drug": a, "barrier": b})
    back = read_objects(tmp_path / "x.3mf")
    assert set(back) == {"drug", "barrier"}
    assert back["barrier"].volume == pytest.approx(8.0) and back["barrier"].bounds[0][0] == pytest.approx(2.0)


def test_a_small_run_writes_both_materials_and_resumes_as_finished(tmp_path, monkeypatch):
    monkeypatch.setattr(twomaterial_outputs, "REFERENCE_MODULE", "design.forward.no_such_module")
    settings = TwoMaterialSettings(DELAY, 0.25, resolution=16, max_iter=12, stages=2)
    result = run_two_material(settings, tmp_path)
    s = result.summary
    for name in ("design.stl", "barrier.stl", "design.3mf", "release.csv", "materials.png", "feasibility.txt"):
        assert (tmp_path / name).is_file()
    assert set(read_objects(tmp_path / "design.3mf")) == {"drug", "barrier"}
    assert 1 <= s["evaluations"] <= 12 and s["reference_fit"] is None and "not installed" in s["reference"]
    assert s["barrier"]["cover_mm"] > 0.4 and s["barrier"]["release_starts_mm"] > 1.6
    assert json.loads((tmp_path / "config.json").read_text())["kind"] == "two-material"
    again = run_two_material(None, tmp_path, resume=True)
    assert again.unchanged and again.summary == json.loads((tmp_path / "summary.json").read_text())


def test_the_start_layout_holds_the_target_volume():
    p = prepare_two(TwoMaterialSettings(DELAY, 0.25, resolution=32))
    x0 = start_layout(p)
    drug = np.sum(x0[0] * (x0[1] == 1.0)) * p.space.dx_mm ** 3 * 8
    assert drug == pytest.approx(p.target.final_mm3, rel=0.25)    # the column's side rounded to whole voxels
    assert target_phases(p.target).delay_mm == pytest.approx(2.0, abs=0.02)


def test_a_stopped_run_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    monkeypatch.setattr(twomaterial_outputs, "REFERENCE_MODULE", "design.forward.no_such_module")
    settings = TwoMaterialSettings(DELAY, 0.25, resolution=16, max_iter=24, stages=2)
    seen = []
    stopped = run_two_material(settings, tmp_path, on_iteration=lambda k, t: seen.append(k),
                               should_stop=lambda: len(seen) >= 5)
    assert stopped.status == "stopped" and stopped.summary is None and not (tmp_path / "summary.json").exists()
    resumed = run_two_material(None, tmp_path, resume=True, on_iteration=lambda k, t: seen.append(k))
    assert resumed.summary is not None and seen[5] == 6          # evaluations count on from the checkpoint
    assert resumed.summary["evaluations"] <= 24
