"""`sfr simulate DRUG --barrier BARRIER --barrier-speed S`: two meshes on one grid, the drug's release, sealed drug."""
import json

import numpy as np
import pytest
import trimesh

from design.errors import DesignError
from design.forward.solid_lattice import TooThinError
from labapp.cli.main import main
from labapp.errors import UsageError
from labapp.jobs.simulate_barrier import simulate_barrier


@pytest.fixture
def meshes(tmp_path):
    """A 4 mm drug cube; a 6 x 6 x 5 mm barrier box flush with its top face (open top); a 6 mm barrier cube
    around it (closed, 1 mm coat). At resolution 24 (dx = 0.25 mm) every face lies on voxel faces."""
    paths = {}
    for name, extents, shift in (("drug", (4, 4, 4), (0, 0, 0)), ("cup", (6, 6, 5), (0, 0, -0.5)),
                                 ("coat", (6, 6, 6), (0, 0, 0))):
        mesh = trimesh.creation.box(extents=extents)
        mesh.apply_translation(shift)
        paths[name] = str(tmp_path / f"{name}.stl")
        mesh.export(paths[name])
    return paths


def _curve(out):
    return np.loadtxt(out / "release.csv", delimiter=",", skiprows=1)


def test_an_insoluble_cup_releases_through_its_opening_only(meshes, tmp_path):
    result = simulate_barrier(meshes["drug"], meshes["cup"], tmp_path / "run", barrier_speed=0.0, resolution=24)
    curve = _curve(result.out)
    # only the 4 x 4 mm top face is open: a plane front, exact on the grid (round-off only)
    np.testing.assert_allclose(curve[:, 1], 16.0 * np.minimum(curve[:, 0], 4.0), rtol=0, atol=1e-6)
    s = result.summary
    assert s["volume_mm3"] == pytest.approx(64.0) and s["sealed_mm3"] == 0.0 and s["sealed_regions_mm3"] == []
    assert s["barrier_volume_mm3"] == pytest.approx(6 * 6 * 5 - 64.0) and s["overlap_voxels"] == 16 ** 3
    assert s["barrier_speed"] == 0.0 and not result.warnings
    assert s["barrier_cover_mm"] < 1e-6 and s["release_starts_mm"] == 0.0
    assert (result.out / "release.png").stat().st_size > 10_000


def test_a_soluble_coat_delays_the_cube(meshes, tmp_path):
    result = simulate_barrier(meshes["drug"], meshes["coat"], tmp_path / "run", barrier_speed=0.5, resolution=24)
    tau, released = _curve(result.out).T
    # the coat (1 mm at half the drug's speed) is crossed at tau = 2; the cube then erodes from all faces
    # the cover: 4 voxels of coat, exact through the faces; the marcher's three-term solves at the coat's
    # corners come 0.08 dx short (observed 0.9808 mm): bound 0.1 dx
    assert result.summary["barrier_cover_mm"] == pytest.approx(1.0, abs=0.025)
    assert result.summary["release_starts_mm"] == pytest.approx(2.0, abs=0.05)
    exact = 64.0 - np.clip(4.0 - 2.0 * np.clip(tau - 2.0, 0, None), 0, None) ** 3
    # nothing before the coat is crossed, less one voxel: eq. (6) spreads a voxel's release over the voxel's
    # crossing time before u, and the marcher's corner voxels (three-term solves) lie up to 0.6 dx early
    assert np.all(released[tau < 2.0 - 0.25] == 0.0)
    # planar fronts are exact; the edge and corner voxels err (first order in dx, over a region that shrinks
    # with dx): observed 2.12 % of the volume at tau = 2 with 16 voxels across the drug (0.56 % with 32);
    # the bound is 1.25 x that
    assert np.abs(released - exact).max() / 64.0 < 0.0265
    # the summary's first-order estimate (against voxels twice as large) covers the true error: observed 5.6 %
    assert np.abs(released - exact).max() / 64.0 <= result.summary["error"]["error_fraction"] < 0.07


def test_drug_sealed_in_an_insoluble_coat_is_reported(meshes, tmp_path):
    result = simulate_barrier(meshes["drug"], meshes["coat"], tmp_path / "run", barrier_speed=0.0, resolution=24)
    assert np.all(_curve(result.out)[:, 1] == 0.0)
    s = json.loads((result.out / "summary.json").read_text())
    assert s["sealed_mm3"] == pytest.approx(64.0) and s["sealed_regions_mm3"] == [pytest.approx(64.0)]
    assert s["barrier_cover_mm"] == pytest.approx(1.0, abs=0.025) and s["release_starts_mm"] is None
    assert any("sealed inside the insoluble barrier in 1 region" in w for w in s["warnings"])


def test_mirror_planes_through_both_meshes_give_the_full_release(meshes, tmp_path):
    full = simulate_barrier(meshes["drug"], meshes["coat"], tmp_path / "full", barrier_speed=0.5, resolution=16)
    octant = simulate_barrier(meshes["drug"], meshes["coat"], tmp_path / "octant", barrier_speed=0.5, resolution=16,
                              symmetry="xyz")
    assert octant.summary["grid_shape"] == [8, 8, 8] and octant.summary["mirror"] == [True, True, True]
    # the same discrete equations on the mirrored part: equal to round-off, volumes the full object's
    np.testing.assert_allclose(_curve(octant.out), _curve(full.out), rtol=1e-9, atol=1e-9)
    assert octant.summary["overlap_voxels"] * 8 == full.summary["overlap_voxels"]
    # the cup is not symmetric about the z mid-plane of the box holding both meshes
    with pytest.raises(DesignError, match="barrier mesh .* no mirror image"):
        simulate_barrier(meshes["drug"], meshes["cup"], tmp_path / "z", barrier_speed=0.5, resolution=16, symmetry="z")


def test_the_grid_covers_both_meshes_and_the_drug_wins():
    from design.files.twogrid import two_material_grid

    drug = trimesh.creation.box(extents=(2, 2, 2))
    barrier = trimesh.creation.box(extents=(2, 2, 2))
    barrier.apply_translation((1, 0, 0))             # half inside the drug, half beside it
    grid = two_material_grid(drug, barrier, voxel_size_mm=0.5)
    assert grid.rho_d.shape == (6, 4, 4) and grid.origin_mm.tolist() == [-1.0, -1.0, -1.0]
    assert grid.rho_d.sum() == 64 and grid.rho_b.sum() == 32 and grid.overlap_voxels == 32
    assert np.all(grid.rho_d + grid.rho_b <= 1.0)
    with pytest.raises(DesignError, match="either resolution or voxel_size_mm"):
        two_material_grid(drug, barrier, resolution=8, voxel_size_mm=0.5)
    with pytest.raises(DesignError, match="holds no voxel centre"):
        two_material_grid(trimesh.creation.box(extents=(0.1, 0.1, 0.1)), barrier, voxel_size_mm=0.5)


def test_bad_inputs_are_refused_before_any_work(meshes, tmp_path):
    np.save(tmp_path / "rho.npy", np.ones((4, 4, 4)))
    with pytest.raises(UsageError, match="must be a mesh"):
        simulate_barrier(meshes["drug"], str(tmp_path / "rho.npy"), tmp_path / "a", barrier_speed=0.5)
    with pytest.raises(UsageError, match="barrier-speed"):
        simulate_barrier(meshes["drug"], meshes["cup"], tmp_path / "b", barrier_speed=-1.0)
    with pytest.raises(DesignError, match="no such file"):
        simulate_barrier(meshes["drug"], str(tmp_path / "missing.stl"), tmp_path / "c", barrier_speed=0.5)
    for name in "abc":
        assert not (tmp_path / name).exists()

def test_the_command_simulates_the_drug_inside_the_barrier(meshes, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", meshes["drug"], "--barrier", meshes["coat"], "--barrier-speed", "0",
                 "--model", "grid", "--resolution", "24", "--out", str(out)]) == 0
    captured = capsys.readouterr().out
    assert "drug 64.0 mm^3 in 152.0 mm^3 of barrier at speed 0" in captured
    assert "barrier cover: at least 0.981 mm of barrier between the outside and the drug" in captured
    assert "the drug is sealed" in captured and "sealed: 64 mm^3 of drug in 1 region(s) never releases" in captured
    assert np.all(_curve(out)[:, 1] == 0.0)
    assert main(["simulate", meshes["drug"], "--barrier", meshes["cup"], "--barrier-speed", "0.5",
                 "--model", "grid", "--resolution", "24", "--out", str(tmp_path / "open")]) == 0
    assert "barrier cover: none, some drug is open to the bath" in capsys.readouterr().out
    # a second run into the same folder is refused: the record is kept
    assert main(["simulate", meshes["drug"], "--barrier", meshes["cup"], "--barrier-speed", "0",
                 "--model", "grid", "--resolution", "24", "--out", str(out)]) == 2
    assert np.all(_curve(out)[:, 1] == 0.0)


def test_the_exact_model_is_the_default(meshes, tmp_path, capsys):
    # the 4 mm cube in the cup open at its top at s = 0.5: the top face releases 16 mm^3 per mm (its sides and bottom
    # are behind 1 mm of barrier, crossed at tau = 2, from then the box's sides erode too): exact distances
    out = tmp_path / "run"
    assert main(["simulate", meshes["drug"], "--barrier", meshes["cup"], "--barrier-speed", "0.5",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "exact model (exact-distance, two materials)" in printed and "error: within" in printed
    curve = _curve(out)
    tau = curve[:, 0]
    late = np.clip(tau - 2.0, 0, None)
    left = np.clip(4.0 - 2.0 * late, 0, None) ** 2 * np.clip(4.0 - tau - late, 0, None)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["model"] == "exact" and summary["error"]["error_fraction"] <= 0.004
    assert np.abs(curve[:, 1] - (64.0 - left)).max() <= summary["error"]["error_mm3"]


def test_a_part_over_the_exact_models_budget_is_refused_naming_the_grid_model(meshes, tmp_path, monkeypatch, capsys):
    # the two-material evaluator refuses a part whose stated error needs more than its lattice budget
    # (design.forward.twomaterial_reference.MAX_POINTS): exit 2, the spacing it needs and --model grid, no folder
    import design.forward.twomaterial_reference as reference

    def refuse(*args, **kwargs):
        raise TooThinError("too many points", 4.0, 0.0889, 2.1e6)
    monkeypatch.setattr(reference, "two_material_reference_release", refuse)
    out = tmp_path / "run"
    assert main(["simulate", meshes["drug"], "--barrier", meshes["coat"], "--barrier-speed", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "needs a lattice of about 0.0889 mm" in err and "about 2.1 million points, over the 0.15 million" in err
    assert "--model grid" in err and not out.exists()


@pytest.mark.parametrize("extra, message", [
    (["--barrier", "{cup}"], "--barrier needs --barrier-speed"),
    (["--barrier-speed", "0.5"], "give --barrier MESH"),
    (["--barrier", "{cup}", "--barrier-speed", "0.5", "--simcal", "{npy}"], "does not take --simcal"),
    (["--barrier", "{cup}", "--barrier-speed", "0.5", "--model", "mc"], "does not take --model mc"),
    (["--barrier", "{cup}", "--barrier-speed", "0.5", "--resolution", "24"], "set the grid model's voxels"),
    (["--barrier", "{npy}", "--barrier-speed", "0.5"], "must be a mesh"),
])
def test_the_command_refuses_what_does_not_apply(meshes, tmp_path, capsys, extra, message):
    np.save(tmp_path / "rho.npy", np.ones((4, 4, 4)))
    argv = [a.format(cup=meshes["cup"], npy=tmp_path / "rho.npy") for a in extra]
    assert main(["simulate", meshes["drug"], *argv, "--out", str(tmp_path / "run")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_a_negative_barrier_speed_is_a_parser_error(meshes, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", meshes["drug"], "--barrier", meshes["cup"], "--barrier-speed", "-1", "--out", str(tmp_path)])
    assert exc.value.code == 2 and "--barrier-speed: '-1': expected a number >= 0" in capsys.readouterr().err
