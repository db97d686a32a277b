"""The design report picture: a long title is wrapped inside the figure, and the slices have axes in mm."""
import numpy as np

from design.files.report import TITLE_CHARS, report_figure, wrap_title

TITLE = ("analytic:zero-order,final=1200mm3,duration=1.87503mm | extruded | print rel. RMSE 10.377% (+/- 0.906%) | "
         "design grid: density 12.18%, binary 12.02% | overhang 3.2% | 20 it. | preset paper:design-4")


def _figure(title: str = TITLE, dx_mm: float | None = 0.5):
    tau = np.linspace(0.0, 3.0, 301)
    curve = np.minimum(tau, 2.0) * 600.0
    rho = np.zeros((20, 20, 12))
    rho[4:16, 4:16, :] = 1.0
    return report_figure(tau, curve, curve, curve, curve, rho, rho > 0.5, title, dx_mm=dx_mm)


def test_a_long_title_is_wrapped_at_its_separators_and_drawn_inside_the_figure():
    wrapped = wrap_title(TITLE)
    assert wrapped.replace("\n", " | ") == TITLE and all(len(line) <= TITLE_CHARS for line in wrapped.splitlines())
    fig = _figure()
    fig.canvas.draw()
    box = fig._suptitle.get_window_extent()
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width and box.y1 <= fig.bbox.height


def test_the_slices_have_axes_in_mm_with_z_up_on_the_vertical_slice():
    fig = _figure()
    slices = fig.axes[2:]
    assert [(a.get_xlabel(), a.get_ylabel()) for a in slices] == [("y (mm)", "z (mm)")] * 2 + [("x (mm)", "y (mm)")] * 2
    assert all(a.axison for a in slices)
    assert slices[0].get_title() == "density, mid-slice x = 5.25 mm"
    assert slices[0].get_xlim() == (0.0, 10.0) and slices[0].get_ylim() == (0.0, 6.0)      # 20 x 12 voxels of 0.5 mm
    assert _figure(dx_mm=None).axes[2].get_xlabel() == "y (voxels)"
