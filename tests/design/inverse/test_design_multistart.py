"""Multi-start: coarse seeded starts, the best refined at full resolution; below the multi-start resolution,
whole starts from each start outline, the best print kept; interpolation between grids."""
import json
import logging

import numpy as np
import pytest

import design.inverse.multistart
from design.errors import DesignError
from design.files.records import load_checkpoint
from design.files.rundir import run_design
from design.inverse.config import DesignConfig
from design.inverse.multistart import coarse_resolution, perturbed_start, refinement_config, upsample
from design.inverse.problem import prepare
from design.inverse.settings import CURVE_EXTRUDED_STARTS, MULTISTART_STARTS


def test_upsample_keeps_a_linear_field_and_the_mirror_face():
    dx_c, dx = 1.0, 0.5
    xc = np.add.outer(0.1 * (np.arange(6) + 0.5), 0.05 * (np.arange(5) + 0.5))  # linear in the centres
    fine = upsample(xc, dx_c, (12, 10), dx)
    centres = [(np.arange(n) + 0.5) * dx for n in (12, 10)]
    expected = np.add.outer(0.1 * centres[0], 0.05 * centres[1])
    inner = (slice(1, -1), slice(1, -1))  # the outermost half voxel is held constant
    np.testing.assert_allclose(fine[inner], expected[inner], atol=1e-12)


def test_coarse_resolution_halves_and_stays_even_from_the_multistart_resolution_on():
    assert coarse_resolution(128) == 64 and coarse_resolution(258) == 128 and coarse_resolution(130) == 64
    # below it the starts run at the run's own resolution
    assert coarse_resolution(66) == 66 and coarse_resolution(16) == 16


@pytest.mark.slow
def test_multistart_runs_the_starts_and_refines_the_best(tmp_path, caplog, monkeypatch):
    # the coarse path, as from resolution 128 on, at a resolution a test can afford
    monkeypatch.setattr(design.inverse.multistart, "MULTISTART_MIN_RESOLUTION", 32)
    config = DesignConfig(target="sphere", space="extruded", resolution=32, max_iter=6, radius_vox=1.5, starts=2)
    phases, firsts = [], {}

    def on_iteration(k, x, terms):
        phases.append(terms["phase"])
        firsts.setdefault(terms["phase"], np.array(x))

    with caplog.at_level(logging.INFO):
        result = run_design(config, tmp_path / "run", on_iteration=on_iteration)
    # a coarse start's own warnings (6 evaluations: not converged) stay the start's: in its summary and at INFO
    # level naming its folder, never as the design's warnings
    start_warnings = json.loads((tmp_path / "run" / "starts" / "00" / "summary.json").read_text())["warnings"]
    assert start_warnings
    infos = [r.getMessage() for r in caplog.records if r.levelno == logging.INFO]
    assert f"{tmp_path / 'run' / 'starts' / '00'}: {start_warnings[0]}" in infos
    warned = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert sorted(warned) == sorted(result.outputs.summary["warnings"]), warned
    # progress names the run each evaluation belongs to
    assert list(dict.fromkeys(phases)) == ["coarse start 1 of 2 at resolution 16",
                                           "coarse start 2 of 2 at resolution 16", "refinement at resolution 32",
                                           "refinement at resolution 32, physical correction round 1 of 2",
                                           "refinement at resolution 32, physical correction round 2 of 2"]
    record = json.loads((tmp_path / "run" / "multistart.json").read_text())
    assert record["coarse_resolution"] == 16 and set(record["best_J"]) == {"00", "01"}
    for k in ("00", "01"):
        coarse = json.loads((tmp_path / "run" / "starts" / k / "summary.json").read_text())
        assert coarse["config"]["resolution"] == 16 and coarse["config"]["starts"] == 1
        assert coarse["rel_rmse_print"] is None and coarse["reference"] is None  # ranked by J: its print not judged
    # the refinement: the extruded REFINE_EVALS_SHARE of 6 evaluations (3), at least the rounds' 2 x 1, then the 2 rounds
    assert result.outputs.summary["config"]["resolution"] == 32 and result.iterations == 3 + 2
    # the refinement started from the chosen start's design interpolated onto its grid (within the session floor of
    # an extruded design's variables, 1e-3)
    with np.load(tmp_path / "run" / "starts" / record["refined"] / "density.npz") as data:
        coarse, dx_coarse = data["rho_hat"], float(data["dx_mm"])
    refined_first = firsts["refinement at resolution 32"]
    start = upsample(coarse, dx_coarse, refined_first.shape, result.outputs.summary["dx_mm"])
    assert np.abs(refined_first - start).max() <= 1.001e-3
    refinement = refinement_config(config)  # the continuation over its own evaluations
    assert (refinement.beta, refinement.beta_final, refinement.max_iter) == (config.beta, config.beta_final, 3 + 2)


def test_perturbed_starts_differ_by_seed_and_start_zero_is_the_default():
    class _Obj:
        def uniform_start(self, region):
            return np.full((8, 8), 0.3)

    class _Prob:
        start_regions = (None,)

    a, b, zero = (perturbed_start(k)(_Obj(), _Prob()) for k in (1, 2, 0))
    assert not np.allclose(a, b) and np.all(zero == 0.3) and a.min() >= 0.02 and a.max() <= 0.98

    class _Outlines:
        start_regions = ("square", "cross")

    class _Marks:
        def uniform_start(self, region):
            return np.full((8, 8), 0.3 if region == "square" else 0.6)

    # the outlines in turn, each unperturbed the first time
    first, second, third = (perturbed_start(k)(_Marks(), _Outlines()) for k in (0, 1, 2))
    assert np.all(first == 0.3) and np.all(second == 0.6) and not np.allclose(third, 0.3)
    with pytest.raises(DesignError, match="starts"):
        DesignConfig(target="sphere", starts=0)


def test_multistart_is_the_default_at_fine_resolutions_only():
    # shapes at resolution 128 or finer, nfc and extruded (docs/design.md#multi-start)
    assert DesignConfig(target="sphere", space="nfc", resolution=128).starts == MULTISTART_STARTS == 4
    assert DesignConfig(target="sphere", space="extruded", resolution=256).starts == 4
    assert DesignConfig(target="sphere", space="extruded", resolution=64).starts == 1
    assert DesignConfig(target="sphere", space="ico", resolution=128).starts == 1
    assert DesignConfig(target="sphere", space="nfc", resolution=128, starts=1).starts == 1
    # curve targets (analytic, CSV, measured) keep one start in nfc, and try each start outline extruded
    assert DesignConfig(target="zero-order", space="nfc", resolution=128).starts == 1
    assert DesignConfig(target="mesh.stl", space="nfc", resolution=128).starts == 4
    assert DesignConfig(target="curve.csv", space="nfc", resolution=128).starts == 1
    assert DesignConfig(target="curve.csv", space="extruded", resolution=40).starts == CURVE_EXTRUDED_STARTS == 3
    assert DesignConfig(target="zero-order", space="extruded", resolution=200).starts == 3


@pytest.mark.slow
def test_whole_starts_from_every_outline_keep_the_best_print(tmp_path):
    # a curve target whose solid square would release its core late: a square, a cross and a ring start, each a
    # whole run with its print corrected; the design is the start whose print fits best, as it is
    config = DesignConfig(target="zero-order:final=0.15,duration=0.2", space="extruded", resolution=24, max_iter=12,
                          w_rate=0.0, robust_eta=0.0)
    assert config.starts == 3 and len(prepare(config).start_regions) == 3
    out = tmp_path / "run"
    result = run_design(config, out)
    record = json.loads((out / "multistart.json").read_text())
    fits = record["print_fit"]
    assert record["resolution"] == 24 and set(fits) == {"00", "01", "02"} and record["chosen"] == min(fits, key=fits.get)
    chosen = out / "starts" / record["chosen"]
    start_summary = json.loads((chosen / "summary.json").read_text())
    assert start_summary["config"]["resolution"] == 24 and start_summary["config"]["starts"] == 1
    assert start_summary["config"]["physical_correction"] == config.physical_correction == "defect"
    # the run's outputs are the chosen start's: its print, its evaluations, its solid
    summary = result.outputs.summary
    assert summary["rel_rmse_print"] == pytest.approx(fits[record["chosen"]], rel=1e-9)
    assert summary["config"]["starts"] == 3 and result.iterations == start_summary["iterations"]
    np.testing.assert_array_equal(load_checkpoint(out / "checkpoint.npz").best_x,
                                  load_checkpoint(chosen / "checkpoint.npz").best_x)
    assert (out / "design.stl").read_bytes() == (chosen / "design.stl").read_bytes()
    # the starts began from their own outlines: different designs
    designs = [load_checkpoint(out / "starts" / name / "checkpoint.npz").best_x for name in sorted(fits)]
    assert all(not np.allclose(designs[i], designs[j]) for i in range(3) for j in range(i))
    # a resume has nothing left to do
    assert run_design(None, out, resume=True).unchanged
