"""The sweep's contact sheet draws each design large enough to see: cropped to its solid, with a scale bar."""
import numpy as np

from labapp.figures.contact_sheet import crop_to_solid, draw_contact_sheet


def _run(folder, size=64, cube=8, dx_mm=0.25):
    folder.mkdir()
    solid = np.zeros((size, size, size), bool)
    lo = size // 2 - cube // 2
    solid[lo:lo + cube, lo:lo + cube, lo:lo + cube] = True
    np.savez(folder / "density.npz", solid=solid, dx_mm=dx_mm)
    tau = np.linspace(0, 2, 5)
    (folder / "curves.csv").write_text("tau_mm,target_mm3,print_mm3\n" + "".join(f"{t},{t},{t}\n" for t in tau))
    return {"name": folder.name, "folder": folder.name, "status": "converged", "rel_rmse_print": 0.01, "pieces": 1}


def test_a_small_design_in_a_large_grid_fills_its_tile(tmp_path, monkeypatch):
    import matplotlib.figure

    drawn = {}
    save = matplotlib.figure.Figure.savefig

    def keep(fig, *args, **kwargs):
        save(fig, *args, **kwargs)
        drawn["fig"] = fig
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    draw_contact_sheet([_run(tmp_path / "a")], tmp_path / "sheet.png")
    fig = drawn["fig"]
    image = next(im for ax in fig.axes for im in ax.get_images())
    cube_px = image.get_window_extent().width * 8 / image.get_array().shape[1]
    assert cube_px >= 40                                  # an 8-voxel cube of a 64^3 grid, not a dozen pixels
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert texts == ["0.5 mm"]                            # 2 mm wide cube: a bar within a third of it


def test_crop_to_solid_keeps_a_margin():
    solid = np.zeros((10, 10, 10), bool)
    solid[4:6, 3:5, 7] = True
    assert crop_to_solid(solid).shape == (4, 4, 3) and crop_to_solid(np.zeros((3, 3, 3), bool)).shape == (3, 3, 3)
