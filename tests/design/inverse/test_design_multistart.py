"""Multi-start: coarse seeded starts, the best refined at full resolution; interpolation between grids."""
import json
import logging

import numpy as np
import pytest

from design.errors import DesignError
from design.files.rundir import run_design
from design.inverse.multistart import coarse_resolution, perturbed_start, upsample
from design.inverse.problem import MULTISTART_STARTS, DesignConfig


def test_upsample_keeps_a_linear_field_and_the_mirror_face():
    dx_c, dx = 1.0, 0.5
    xc = np.add.outer(0.1 * (np.arange(6) + 0.5), 0.05 * (np.arange(5) + 0.5))  # linear in the centres
    fine = upsample(xc, dx_c, (12, 10), dx)
    centres = [(np.arange(n) + 0.5) * dx for n in (12, 10)]
    expected = np.add.outer(0.1 * centres[0], 0.05 * centres[1])
    inner = (slice(1, -1), slice(1, -1))  # the outermost half voxel is held constant
    np.testing.assert_allclose(fine[inner], expected[inner], atol=1e-12)


def test_coarse_resolution_halves_and_stays_even():
    assert coarse_resolution(128) == 64 and coarse_resolution(66) == 32 and coarse_resolution(16) == 16


def test_multistart_runs_the_starts_and_refines_the_best(tmp_path, caplog):
    config = DesignConfig(target="sphere", space="extruded", resolution=32, max_iter=6, radius_vox=1.5, starts=2)
    phases = []
    with caplog.at_level(logging.INFO):
        result = run_design(config, tmp_path / "run", on_iteration=lambda k, x, terms: phases.append(terms["phase"]))
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
                                           "coarse start 2 of 2 at resolution 16", "refinement at resolution 32"]
    record = json.loads((tmp_path / "run" / "multistart.json").read_text())
    assert record["coarse_resolution"] == 16 and set(record["best_J"]) == {"00", "01"}
    for k in ("00", "01"):
        coarse = json.loads((tmp_path / "run" / "starts" / k / "summary.json").read_text())
        assert coarse["config"]["resolution"] == 16 and coarse["config"]["starts"] == 1
    assert result.outputs.summary["config"]["resolution"] == 32 and result.iterations == 6
    # the refinement started from the best start, not from the uniform design: J at its first evaluation
    # is below the uniform start's
    single = run_design(DesignConfig(target="sphere", space="extruded", resolution=32, max_iter=1, radius_vox=1.5),
                        tmp_path / "single")
    refined_first = np.loadtxt(tmp_path / "run" / "history.csv", delimiter=",", skiprows=1)[0, 1]
    assert refined_first < single.best_value


def test_perturbed_starts_differ_by_seed_and_start_zero_is_the_default():
    class _Obj:
        def uniform_start(self, region):
            return np.full((8, 8), 0.3)

    class _Prob:
        start_region = None

    a, b, zero = (perturbed_start(k)(_Obj(), _Prob()) for k in (1, 2, 0))
    assert not np.allclose(a, b) and np.all(zero == 0.3) and a.min() >= 0.02 and a.max() <= 0.98
    with pytest.raises(DesignError, match="starts"):
        DesignConfig(target="sphere", starts=0)


def test_multistart_is_the_default_at_fine_resolutions_only():
    # shapes at resolution 128 or finer, nfc and extruded (docs/design.md#multi-start)
    assert DesignConfig(target="sphere", space="nfc", resolution=128).starts == MULTISTART_STARTS == 4
    assert DesignConfig(target="sphere", space="extruded", resolution=256).starts == 4
    assert DesignConfig(target="sphere", space="extruded", resolution=64).starts == 1
    assert DesignConfig(target="sphere", space="ico", resolution=128).starts == 1
    assert DesignConfig(target="sphere", space="nfc", resolution=128, starts=1).starts == 1
    # curve targets (analytic, CSV, measured) keep one start
    assert DesignConfig(target="zero-order", space="nfc", resolution=128).starts == 1
    assert DesignConfig(target="mesh.stl", space="nfc", resolution=128).starts == 4
    assert DesignConfig(target="curve.csv", space="nfc", resolution=128).starts == 1
