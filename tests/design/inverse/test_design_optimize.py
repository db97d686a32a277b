"""The design run: outputs, checkpoints, stop, Ctrl-C and resume (tiny grids, few evaluations)."""
import json

import numpy as np
import pytest
import trimesh

from design.errors import DesignError
from design.fabrication.connectivity import Connectivity
from design.files.outputs import _rate_dev
from design.files.rundir import run_design
from design.forward.reference import reference_release
from design.geometry.shapes import sample_shape
from design.inverse.config import DesignConfig
from design.inverse.objective import rel_rmse
from design.inverse.problem import prepare
from design.inverse.status import FINISHED, DesignStatus
from design.material import PRINT_DENSITY_G_PER_CM3

SMALL = dict(target="sphere", space="nfc", resolution=16, radius_vox=2.0, checkpoint_every=3)


def test_sphere_run_writes_every_output_and_fits(tmp_path):
    result = run_design(DesignConfig(max_iter=80, formats=("3mf", "obj"), **SMALL), tmp_path / "run")
    out = tmp_path / "run"
    for name in ("design.stl", "design.3mf", "design.obj", "density.npz", "curves.csv", "report.png", "history.csv",
                 "summary.json", "design.ini", "config.json", "checkpoint.npz"):
        assert (out / name).exists(), name
    summary = json.loads((out / "summary.json").read_text())
    for key in ("rel_rmse_print", "rel_rmse_print_error", "rel_rmse_density", "rel_rmse_design_grid_binary",
                "iterations", "seconds", "seconds_per_iteration", "pieces", "print_mass_g", "min_channel_mm",
                "enclosed_voids", "enclosed_void_mm3"):
        assert key in summary
    assert summary["enclosed_voids"] == 0 and summary["enclosed_void_mm3"] == 0.0  # a sphere's design is solid
    assert summary["software"]["numpy"] == np.__version__ and summary["software"]["shape-from-release"]
    assert (out / "curves.csv").read_text().splitlines()[0] == "tau_mm,target_mm3,print_mm3,density_mm3,binary_mm3"
    # the mesh target is the sphere's physical release: it ends at the mesh's volume and starts at 0
    curves = np.genfromtxt(out / "curves.csv", delimiter=",", names=True)
    assert curves["target_mm3"][-1] == pytest.approx(sample_shape("sphere").volume, rel=1e-9)
    assert curves["target_mm3"][0] == 0.0 and curves["print_mm3"][0] == 0.0
    history = np.loadtxt(out / "history.csv", delimiter=",", skiprows=1)
    assert result.iterations == len(history) <= 80
    assert history[-1, 1] < history[0, 1] / 5  # J falls well below the uniform start
    # an 8^3 octant recovers the sphere's curve to a few percent within 80 evaluations (20 per beta stage)
    assert summary["rel_rmse_print"] < 0.05 and summary["pieces"] == 1
    assert summary["config"]["w_binary"] == 20.0  # defaults are resolved and stored
    # volume_mm3, print_mass_g and the headline fit recomputed from design.stl: its volume (to the float32
    # coordinates of an STL), and its release by the reference evaluator on another lattice (an
    # independent quadrature), within the stated errors of both
    mesh = trimesh.load(out / "design.stl")
    assert summary["volume_mm3"] == pytest.approx(mesh.volume, rel=1e-6)
    assert summary["print_mass_g"] == pytest.approx(summary["volume_mm3"] * PRINT_DENSITY_G_PER_CM3 / 1000, rel=1e-12)
    again = reference_release(mesh, curves["tau_mm"], cells=80)
    stated = summary["reference"]["print_error_mm3"] + again.error_mm3
    assert np.abs(again.released_mm3 - curves["print_mm3"]).max() <= stated
    fit = rel_rmse(again.released_mm3, curves["target_mm3"])
    assert abs(fit - summary["rel_rmse_print"]) <= stated / curves["target_mm3"][-1]
    assert summary["rel_rmse_print_error"] >= summary["reference"]["print_error_mm3"] / curves["target_mm3"][-1]
    assert summary["rel_rmse_print"] == pytest.approx(rel_rmse(curves["print_mm3"], curves["target_mm3"]), rel=1e-6)


def test_stop_then_resume_continues_the_history(tmp_path):
    config = DesignConfig(max_iter=12, **SMALL)
    calls = []
    first = run_design(config, tmp_path, should_stop=lambda: len(calls) >= 5,
                       on_iteration=lambda k, x, terms: calls.append((k, terms["eta_s"])))
    assert first.status == "stopped" and first.iterations == 5
    # the best design so far is written at a clean stop (after 5 evaluations it may still be grey)
    assert (tmp_path / "density.npz").exists() and (tmp_path / "summary.json").exists()
    with pytest.raises(DesignError, match="already holds a design run"):
        run_design(config, tmp_path)
    second = run_design(None, tmp_path, resume=True)
    history = np.loadtxt(tmp_path / "history.csv", delimiter=",", skiprows=1)
    assert second.iterations == 12 and list(history[:, 0]) == list(range(1, 13))
    assert np.all(np.diff(history[:, -1]) > 0)  # elapsed time keeps counting across sessions


def test_ctrl_c_stops_cleanly_with_the_best_design(tmp_path):
    def interrupt(k, x, terms):
        if k == 4:
            raise KeyboardInterrupt

    result = run_design(DesignConfig(max_iter=30, **SMALL), tmp_path, on_iteration=interrupt)
    assert result.status == "interrupted" and result.iterations == 4
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "interrupted"


def test_configuration_guards(tmp_path):
    with pytest.raises(DesignError, match="16 layers need at least as many elasticity elements along z"):
        prepare(DesignConfig(target="sphere", space="ico", resolution=16, layers=16))
    with pytest.raises(DesignError, match="even number"):
        DesignConfig(target="sphere", resolution=15)
    with pytest.raises(DesignError, match="neither a sample shape"):
        prepare(DesignConfig(target="teapot", resolution=16))
    with pytest.raises(DesignError, match="no readable config.json"):
        run_design(None, tmp_path / "nothing", resume=True)
    with pytest.raises(DesignError, match="infeasible"):
        run_design(DesignConfig(target="zero-order:final=0.5,duration=1.0", resolution=16), tmp_path / "bad")


def test_beta_continuation_defaults_and_stored_fixed_runs(tmp_path):
    assert DesignConfig(target="sphere", space="nfc").beta_final == 12.0
    assert DesignConfig(target="sphere", space="extruded").beta_final == 12.0
    assert DesignConfig(target="sphere", space="nfc", beta=20.0).beta_final == 20.0  # never below beta
    assert DesignConfig(target="sphere", space="ico").beta_final is None  # fixed
    preset = DesignConfig(target="pill", space="extruded", preset="paper:pill")
    assert preset.beta_final == preset.beta  # the paper's fixed projection
    # a run stored before the default (beta_final null meant a fixed beta) resumes with a fixed beta
    config = DesignConfig(max_iter=6, **SMALL)
    run_design(config, tmp_path, should_stop=lambda: True)
    stored = json.loads((tmp_path / "config.json").read_text())
    stored["beta_final"] = None
    (tmp_path / "config.json").write_text(json.dumps(stored))
    run_design(None, tmp_path, resume=True)
    resumed = json.loads((tmp_path / "summary.json").read_text())["config"]
    assert resumed["beta_final"] == resumed["beta"]


@pytest.mark.slow
def test_an_extruded_ring_opens_its_hole_with_default_flags(tmp_path):
    # a ring 6 mm tall with a 5 mm wall ends its release at 2.5 mm, before its faces (3 mm) dissolve a
    # solid core: a start whose core is solid would keep it; the start without it opens the hole, in
    # one piece (docs/design.md#extruded-start)
    trimesh.creation.annulus(r_min=3.0, r_max=8.0, height=6.0, sections=64).export(tmp_path / "ring.stl")
    run_design(DesignConfig(target=str(tmp_path / "ring.stl"), space="extruded", resolution=48, max_iter=150),
               tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    # the print's true fit at this small resolution and budget (1.1% measured); the 1% of an extrusion's
    # acceptance figure is for resolution 128
    assert summary["rel_rmse_print"] < 0.015 and summary["pieces"] == 1
    with np.load(tmp_path / "run" / "density.npz") as saved:
        solid = saved["solid"]
    centre = tuple(n // 2 for n in solid.shape)
    assert not solid[centre]  # the hole goes through the middle of the extrusion


def test_a_run_stored_before_the_plane_term_and_the_tail_resumes_with_the_bounded_core_term_alone(tmp_path):
    config = DesignConfig(max_iter=6, **SMALL)
    assert config.connect_planes
    run_design(config, tmp_path, should_stop=lambda: True)
    stored = json.loads((tmp_path / "config.json").read_text())
    del stored["format"], stored["connect_planes"], stored["connect_tail"]  # layout 0, before the options
    (tmp_path / "config.json").write_text(json.dumps(stored))
    run_design(None, tmp_path, resume=True)
    resumed = json.loads((tmp_path / "summary.json").read_text())["config"]
    assert resumed["connect_planes"] is False and resumed["connect_tail"] == 0.0
    # the core term alone is the plane term's absence: a floating blob pays its volume once, not twice
    blob = np.zeros((12, 12))
    blob[0:4, 0:4] = blob[8:11, 8:11] = 1.0
    core_only = Connectivity(blob.shape, (True, True), 0.5, planes=False, tail_slope=0.0)(blob, 1.0)[0]
    both = Connectivity(blob.shape, (True, True), 0.5, tail_slope=0.0)(blob, 1.0)[0]
    assert core_only == pytest.approx(9.0, rel=0.02) and both == pytest.approx(18.0, rel=0.02)


def test_a_release_over_within_one_sample_has_no_rate_deviation_instead_of_failing_the_outputs():
    tau = np.linspace(0.0, 1.0, 11)
    curve = np.full(11, 10.0)
    curve[0] = 0.0
    curve[5] -= 1e-12  # all released by the first sample, with round-off: not monotone
    assert _rate_dev(tau, curve, 10.0 * tau, vs_target=False) is None
    assert _rate_dev(tau, curve, 10.0 * tau, vs_target=True) is not None  # the target's window is well defined


def test_a_curve_target_is_taken_as_given(tmp_path):
    run_design(DesignConfig(target="zero-order:final=0.1,duration=0.3", space="nfc", resolution=16, max_iter=4),
               tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["reference"] is None or summary["reference"]["target_error_mm3"] is None


def test_a_source_target_is_the_whole_source_s_physical_release(tmp_path):
    """The spinner top is not symmetric about its mid-height plane while an nfc design is: the target is
    the whole source's release by exact distances, which ends at its volume, whatever the design grid."""
    problem = prepare(DesignConfig(target="spinner_top", space="nfc", resolution=16, radius_vox=2.0))
    volume = sample_shape("spinner_top").volume
    assert problem.target.released_mm3[-1] == pytest.approx(volume, rel=1e-9)
    assert problem.target.released_mm3[0] == 0.0
    assert problem.target_error_mm3 <= 0.002 * volume


def test_a_design_status_is_its_stored_string():
    assert [str(s) for s in DesignStatus] == ["converged", "max_iter", "stalled", "stopped", "interrupted"]
    assert json.dumps({"status": DesignStatus.MAX_ITER}) == '{"status": "max_iter"}'
    assert DesignStatus("stopped") == "stopped" and f"{DesignStatus.STALLED}" == "stalled"
    assert [s for s in DesignStatus if s.finished] == list(FINISHED) == ["converged", "max_iter", "stalled"]


@pytest.mark.parametrize("space, ndim", [("nfc", 3), ("extruded", 2)])
def test_progress_gets_the_design_variables_in_their_shape(tmp_path, space, ndim):
    seen = []
    result = run_design(DesignConfig(**dict(SMALL, space=space), max_iter=3), tmp_path,
                        on_iteration=lambda k, x, terms: seen.append((k, x.shape, x.flags.writeable, x.copy())))
    shape = prepare(DesignConfig(**dict(SMALL, space=space))).space.var_shape
    assert len(shape) == ndim and [s[:3] for s in seen] == [(k, shape, False) for k in (1, 2, 3)]
    with np.load(tmp_path / "checkpoint.npz") as saved:
        np.testing.assert_array_equal(seen[-1][3].ravel(), saved["x"])  # the last evaluated design
    assert result.iterations == 3
