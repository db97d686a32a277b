"""The bench window's frame: docks, scrolled forms, menus from (text, slot, shortcut) rows, the run's progress
in the status bar, and the window fitted to the screen. What the window's parts do is the main window's."""
from __future__ import annotations

from collections.abc import Callable, Iterable

from PySide6.QtCore import QRect, Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (
    QDockWidget,
    QLabel,
    QMainWindow,
    QMenu,
    QProgressBar,
    QScrollArea,
    QSizePolicy,
    QSplitter,
    QTabWidget,
    QWidget,
)

from labapp.gui.plots import hmm

PREFERRED_SIZE = (1500, 950)
"""The window's size where the screen has room; smaller screens get their available area."""
TITLE_BAR_PX = 32
"""Room left for the window manager's title bar when fitting the window to the screen."""
LOG_HEIGHT_PX = 110
BENCH_DOCK_MAX_SHARE = 0.4
"""The bench dock takes at most this share of the window's width when the window is fitted to the screen."""
BENCH_DOCK_SLACK_PX = 12
"""Pixels the bench dock gets beyond its widest tab's minimum (the dock's own frame and splitter)."""

MenuRow = tuple[str, Callable, QKeySequence.StandardKey | str | None]
"""A menu entry: its text, the slot its action triggers and its shortcut (None: none)."""


def scrolled(widget: QWidget) -> QScrollArea:
    """``widget`` in a scroll area: a long form never forces the dock wider or taller than the screen."""
    area = QScrollArea()
    area.setWidget(widget)
    area.setWidgetResizable(True)
    area.setFrameShape(QScrollArea.Shape.NoFrame)
    area.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAsNeeded)
    return area


def side_by_side(left: QWidget, right: QWidget) -> QSplitter:
    """``left`` and ``right`` sharing the width equally, neither collapsible."""
    split = QSplitter()
    split.addWidget(left)
    split.addWidget(right)
    split.setStretchFactor(0, 1)
    split.setStretchFactor(1, 1)
    split.setChildrenCollapsible(False)
    return split


def add_dock(window: QMainWindow, title: str, widget: QWidget, area: Qt.DockWidgetArea) -> QDockWidget:
    """A dock named ``title`` holding ``widget``, added to ``window`` at ``area``."""
    dock = QDockWidget(title, window)
    dock.setObjectName(title)
    dock.setWidget(widget)
    window.addDockWidget(area, dock)
    return dock


def add_menu(window: QMainWindow, title: str, rows: Iterable[MenuRow] = ()) -> QMenu:
    """A menu of ``window``'s menu bar with one action per row (:func:`add_actions`)."""
    menu = window.menuBar().addMenu(title)
    add_actions(window, menu, rows)
    return menu


def add_actions(window: QMainWindow, menu: QMenu, rows: Iterable[MenuRow]) -> None:
    """Append one action of ``window`` per row to ``menu``."""
    for text, slot, shortcut in rows:
        action = QAction(text, window)
        action.triggered.connect(slot)
        if shortcut is not None:
            action.setShortcut(QKeySequence(shortcut))
        menu.addAction(action)


def bench_width(tabs: QTabWidget) -> int:
    """Width (px) at which the widest tab of ``tabs`` (each a :func:`scrolled` form) shows without a horizontal
    scroll bar."""
    areas = [tabs.widget(i) for i in range(tabs.count())]
    content = max(area.widget().minimumSizeHint().width() for area in areas)
    scroll_bar = max(area.verticalScrollBar().sizeHint().width() for area in areas)
    frames = tabs.sizeHint().width() - tabs.currentWidget().sizeHint().width()
    return content + scroll_bar + max(frames, 0) + BENCH_DOCK_SLACK_PX


def fit_to_screen(window: QMainWindow, available: QRect, bench_dock: QDockWidget, bench_tabs: QTabWidget) -> None:
    """Size ``window`` to :data:`PREFERRED_SIZE`, or to ``available`` (less a title bar) where that is smaller,
    place it inside that area and give the bench dock the width its forms need (at most
    :data:`BENCH_DOCK_MAX_SHARE` of the window's)."""
    width = min(PREFERRED_SIZE[0], available.width())
    height = min(PREFERRED_SIZE[1], available.height() - TITLE_BAR_PX)
    window.resize(width, height)
    window.move(available.x() + (available.width() - width) // 2,
                available.y() + max(0, (available.height() - TITLE_BAR_PX - height) // 2))
    window.resizeDocks([bench_dock], [min(bench_width(bench_tabs), int(BENCH_DOCK_MAX_SHARE * width))],
                       Qt.Orientation.Horizontal)


class ElidedLine(QLabel):
    """One line of text that ends in "..." where it does not fit (never under a neighbour); the whole text is its
    tooltip and :attr:`full`."""

    def __init__(self, text: str = "", parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.full = ""
        self.set_line(text)

    def set_line(self, text: str) -> None:
        """Show ``text``, elided to the label's width."""
        if text != self.full:
            self.full = text
            self.setToolTip(text)
            self._elide()

    def resizeEvent(self, event) -> None:  # noqa: N802 (Qt override)
        super().resizeEvent(event)
        self._elide()

    def _elide(self) -> None:
        self.setText(self.fontMetrics().elidedText(self.full, Qt.TextElideMode.ElideRight, max(self.width(), 40)))


class RunProgress(QProgressBar):
    """The recording run's time against its maximum duration, in h:mm (hidden until shown)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setFixedWidth(390)          # the status line beside it gives way, never the bar
        self.setTextVisible(True)
        self.hide()

    def show_time(self, t_s: float, total_s: float, steady_stop: bool) -> None:
        """``t_s`` of ``total_s`` s elapsed (``steady_stop``: the run may stop earlier, at steady state)."""
        self.setRange(0, max(1, int(total_s)))
        self.setValue(int(min(max(t_s, 0.0), total_s)))
        left = max(total_s - t_s, 0.0)
        self.setFormat(f"{hmm(t_s)} of {hmm(total_s)}, {hmm(left)} left"
                       + (" at most (steady-state stop)" if steady_stop else ""))
