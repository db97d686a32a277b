"""The main window at 1280x800 (offscreen): it fits the screen, its docks can come back, and every tab's
plots are tall enough to read."""
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QPoint, QRect

from labapp.gui.main_window import MainWindow
from labapp.gui.window_layout import BENCH_DOCK_MAX_SHARE, PREFERRED_SIZE

SCREEN = QRect(0, 0, 1280, 800)
READABLE_PX = 250


@pytest.fixture
def window(qtbot, tmp_path):
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    win.fit_to_screen(SCREEN)
    win.show()
    qtbot.waitExposed(win)
    yield win
    win.shutdown()


def _inside(win, widget) -> QRect:
    """``widget``'s rectangle in window coordinates."""
    return QRect(widget.mapTo(win, QPoint(0, 0)), widget.size())


def test_window_fits_1280x800_with_log_and_status_bar(window, qtbot):
    assert window.width() <= 1280 and window.height() <= 800 - 30
    assert window.minimumSizeHint().width() <= 1280 and window.minimumSizeHint().height() <= 770
    frame = QRect(0, 0, window.width(), window.height())
    for widget in (window.messages, window.statusBar(), window.bench_dock, window.tabs):
        assert widget.isVisible(), widget
        assert frame.contains(_inside(window, widget)), (widget, _inside(window, widget), frame)
    assert window.messages.height() >= 60
    big = QRect(0, 0, 2560, 1440)
    window.fit_to_screen(big)
    assert (window.width(), window.height()) == PREFERRED_SIZE


def test_plots_are_readable_in_every_tab(window, qtbot):
    checks = {"Live": [window.plots.release_widget, window.plots.bath_widget],
              "Runs": [window.browser.plots.release_widget, window.browser.plots.bath_widget],
              "Design": [window.design.plot, window.design.solid]}
    for index in range(window.tabs.count()):
        name = window.tabs.tabText(index)
        window.tabs.setCurrentIndex(index)
        qtbot.wait(50)
        for plot in checks[name]:
            assert plot.isVisible() and plot.height() >= READABLE_PX, (name, plot, plot.height())
    window.tabs.setCurrentIndex(0)
    qtbot.wait(50)
    # the live frame fills its view: the whole image is in range and touches two opposite edges
    import numpy as np
    window.live.set_frame(np.zeros((1000, 1500, 3), np.uint8), "test")
    qtbot.wait(50)
    (x0, x1), (y0, y1) = window.live.view.viewRange()
    assert x0 <= 0 and y0 <= 0 and x1 >= 1500 and y1 >= 1000
    assert min((x1 - x0) / 1500, (y1 - y0) / 1000) <= 1.02


def test_long_run_names_are_not_cut(window, qtbot, tmp_path):
    browser = window.browser
    browser.tree.resize(700, 300)
    name = "20261202-101500_a-long-run-name-of-the-operator"
    from PySide6.QtWidgets import QTreeWidgetItem
    browser._add_item(tmp_path / name, [name, "run", "complete", "1300", "2026-12-02 10:15"])
    qtbot.wait(50)
    item = browser.tree.topLevelItem(browser.tree.topLevelItemCount() - 1)
    assert isinstance(item, QTreeWidgetItem) and item.toolTip(0).endswith(name)
    width = browser.tree.fontMetrics().horizontalAdvance(name)
    assert browser.tree.columnWidth(0) >= width


def test_view_menu_brings_back_every_dock(window, qtbot):
    actions = {a.text(): a for a in window.view_menu.actions()}
    for dock in (window.bench_dock, window.log_dock):
        dock.close()
        assert not dock.isVisible()
        actions[dock.windowTitle()].trigger()
        assert dock.isVisible()


def test_every_bench_tab_fits_its_dock_without_a_horizontal_scroll_bar(window, qtbot):
    tabs = window.bench_tabs
    for index in range(tabs.count()):
        tabs.setCurrentIndex(index)
        qtbot.wait(50)
        area = tabs.widget(index)
        assert not area.horizontalScrollBar().isVisible(), (tabs.tabText(index), area.widget().minimumSizeHint(),
                                                            area.viewport().width())
    assert window.bench_dock.width() <= BENCH_DOCK_MAX_SHARE * window.width() + 1
