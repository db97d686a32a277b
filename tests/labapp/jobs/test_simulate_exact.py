"""`sfr simulate` by default: the exact model on hard parts, against analytic releases; its refusals and outputs."""
import errno
import json

import numpy as np
import pytest
import trimesh

from labapp.cli.main import main

RMS_TOLERANCE = 0.005
"""The exact model's promise: RMS over the curve within 0.5% of the volume (its stated error aims at 0.4% max)."""


def _box_release(tau, a, b, c):
    """A box's exact release: its volume less the box shrunk by tau on every face."""
    return a * b * c - np.prod(np.clip(np.array([a, b, c]) - 2 * np.asarray(tau)[:, None], 0, None), axis=1)


def _prism_release(tau, r, n, length):
    """An n-gon prism of circumradius r (trimesh's cylinder): its cross-section shrinks about the apothem."""
    apothem = r * np.cos(np.pi / n)
    area = 0.5 * n * r * r * np.sin(2 * np.pi / n)
    t = np.minimum(tau, min(apothem, length / 2))
    return area * length - area * ((apothem - t) / apothem) ** 2 * (length - 2 * t)


def _run(tmp_path, mesh, name, *extra):
    path = tmp_path / f"{name}.stl"
    mesh.export(path)
    out = tmp_path / name
    assert main(["simulate", str(path), "--out", str(out), *extra]) == 0
    curve = np.loadtxt(out / "release.csv", delimiter=",", skiprows=1)
    return curve[:, 0], curve[:, 1], json.loads((out / "summary.json").read_text())


def _rms(released, exact, volume):
    return float(np.sqrt(np.mean((released - exact) ** 2)) / volume)


def test_a_long_rod_is_released_within_its_promise(tmp_path):
    # 20 mm long, 2 mm across (10 diameters): the grid's 64 voxels along it leave it 6 voxels across
    rod = trimesh.creation.cylinder(radius=1.0, height=20.0, sections=32)
    tau, released, summary = _run(tmp_path, rod, "rod")
    exact = _prism_release(tau, 1.0, 32, 20.0)
    assert summary["model"] == "exact" and summary["method"] == "exact-distance"
    # the curve ends at the volume of the mesh as read (the STL's single-precision vertices)
    assert released[-1] == pytest.approx(summary["volume_mm3"], rel=1e-9)
    assert summary["volume_mm3"] == pytest.approx(rod.volume, rel=1e-6)
    assert _rms(released, exact, rod.volume) < RMS_TOLERANCE
    # the stated error bounds the actual one
    assert np.abs(released - exact).max() <= summary["error"]["error_mm3"]
    assert summary["error"]["error_fraction"] <= 0.004 and "mean half-thickness" in summary["lattice"]["reason"]


def test_a_thin_plate_is_released_within_its_promise(tmp_path):
    plate = trimesh.creation.box((40.0, 30.0, 1.0))
    tau, released, summary = _run(tmp_path, plate, "plate")
    exact = _box_release(tau, 40.0, 30.0, 1.0)
    assert released[-1] == pytest.approx(1200.0, rel=1e-6)
    assert _rms(released, exact, 1200.0) < RMS_TOLERANCE / 10
    assert tau[-1] == pytest.approx(0.5, abs=0.2)  # the samples end where the plate is gone, not at its box's half


def test_a_sealed_void_is_wetted_when_the_front_reaches_it(tmp_path):
    # a 10 mm cube around a concentric 4 mm cubic void: the void is wetted at tau = 3, when the outer faces' front
    # reaches it, and the whole solid is gone then; a void open to the bath would release from tau = 0
    outer = trimesh.creation.box((10.0, 10.0, 10.0))
    void = trimesh.creation.box((4.0, 4.0, 4.0))
    void.invert()
    tau, released, summary = _run(tmp_path, trimesh.util.concatenate([outer, void]), "hollow")
    exact = np.minimum(_box_release(tau, 10.0, 10.0, 10.0), 936.0)
    assert summary["method"] == "exact-distance-voids"
    assert _rms(released, exact, 936.0) < RMS_TOLERANCE
    # the stated error bounds the actual one, at the kink where the void is wetted too
    assert np.abs(released - exact).max() <= summary["error"]["error_mm3"]


@pytest.mark.parametrize("gap, one", [(-4.0, True), (3.0, False)])
def test_overlapping_bodies_are_one_solid_and_separate_ones_are_dropped_together(tmp_path, gap, one):
    # two 6 mm cubes along x: overlapping, they are one box; apart, two boxes in the beaker
    a = trimesh.creation.box((6.0, 6.0, 6.0))
    b = trimesh.creation.box((6.0, 6.0, 6.0))
    b.apply_translation([6.0 + gap, 0.0, 0.0])
    tau, released, summary = _run(tmp_path, trimesh.util.concatenate([a, b]), f"two{gap:g}")
    exact = _box_release(tau, 12.0 + gap, 6.0, 6.0) if one else 2 * _box_release(tau, 6.0, 6.0, 6.0)
    volume = exact.max()
    assert released[-1] == pytest.approx(volume, rel=1e-6)
    assert _rms(released, exact, volume) < RMS_TOLERANCE
    assert summary["bodies"] == (1 if one else 2)


def test_touching_bodies_are_one_solid(tmp_path):
    # a 4 mm cube set on a 6 mm one: water never reaches the face they share
    from design.forward.reference import reference_release

    a = trimesh.creation.box((6.0, 6.0, 6.0))
    b = trimesh.creation.box((4.0, 4.0, 4.0))
    b.apply_translation([0.0, 0.0, 5.0])
    tau, released, summary = _run(tmp_path, trimesh.util.concatenate([a, b]), "stacked")
    united = reference_release(trimesh.boolean.union([a, b], engine="manifold"), tau)
    apart = reference_release(trimesh.util.concatenate([a, b]), tau, cells=64)  # their shared face wetted
    assert summary["bodies"] == 1 and released[-1] == pytest.approx(280.0, rel=1e-6)
    assert np.abs(released - united.released_mm3).max() <= united.error_mm3 + summary["error"]["error_mm3"]
    assert np.abs(released - apart.released_mm3).max() > 0.02 * 280.0


def test_a_part_too_thin_is_refused_naming_its_thickness(tmp_path, capsys):
    foil = trimesh.creation.box((40.0, 40.0, 0.02))
    path = tmp_path / "foil.stl"
    foil.export(path)
    assert main(["simulate", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "foil.stl: its features are too thin" in err and "mean thickness 2V/A = 0.02 mm" in err
    assert "--model grid" in err and not (tmp_path / "o").exists()


def test_a_pill_drawn_in_cm_is_warned_about(tmp_path):
    pill = trimesh.creation.capsule(height=1.4, radius=0.45, count=[16, 16])  # 2.3 cm long, read as mm
    _, _, summary = _run(tmp_path, pill, "pill")
    assert any("longest side is 2.3 mm" in w and "--units cm" in w for w in summary["warnings"])
    _, _, summary = _run(tmp_path, pill, "pill_cm", "--units", "cm")
    assert summary["warnings"] == [] and summary["volume_mm3"] == pytest.approx(pill.volume * 1000, rel=1e-6)


def test_grid_options_belong_to_the_grid_model(tmp_path, capsys):
    assert main(["simulate", "sample:sphere", "--symmetry", "xyz", "--out", str(tmp_path / "o")]) == 2
    assert "--symmetry set the grid model's voxels" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "sample:sphere", "--resolution", "7", "--model", "grid", "--out", str(tmp_path / "o")])
    assert exc.value.code == 2
    assert "--resolution: '7': expected a whole number in [8, 1024] voxels" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_two_dimensional_density_is_refused(tmp_path, capsys):
    np.savez(tmp_path / "rho_2d.npz", rho=np.ones((10, 10)), dx_mm=0.5)
    assert main(["simulate", str(tmp_path / "rho_2d.npz"), "--out", str(tmp_path / "o")]) == 2
    assert "rho_2d.npz: its density rho has shape (10, 10); expected a 3-D array" in capsys.readouterr().err


def test_a_full_disk_leaves_no_partial_release(tmp_path, monkeypatch, capsys):
    import labapp.records.fileio as fileio

    real_open = open

    class Full:
        """A file that takes a few bytes, then reports the disk full."""

        def __init__(self, path, mode):
            self.fh = real_open(path, mode)

        def write(self, data):
            self.fh.write(data[:10])
            raise OSError(errno.ENOSPC, "No space left on device")

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    monkeypatch.setattr(fileio, "open", lambda path, mode="r", *a, **k: Full(path, mode), raising=False)
    out = tmp_path / "o"
    assert main(["simulate", "sample:sphere", "--out", str(out)]) != 0
    err = capsys.readouterr().err
    assert f"cannot write {out / 'release.csv'}: No space left on device" in err and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())  # nothing partial, not even a part file


def test_monte_carlo_without_a_calibration_says_so(tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["simulate", "sample:sphere", "--model", "mc", "--resolution", "8", "--seeds", "1",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["calibrated"] is False and "uncalibrated defaults" in summary["calibration_note"]
    assert "uncalibrated defaults" in capsys.readouterr().out
