"""The system libraries Qt's X11 (xcb) platform plugin loads, checked before the QApplication exists, so a
desktop without them gets one line naming the Debian package instead of "Could not load the Qt platform
plugin xcb". This module imports no Qt."""
from __future__ import annotations

import ctypes.util
import os
import subprocess
import sys

XCB_LIBRARIES: tuple[tuple[str, str], ...] = (
    ("xcb-cursor", "libxcb-cursor0"),
    ("xkbcommon-x11", "libxkbcommon-x11-0"),
    ("xcb-icccm", "libxcb-icccm4"),
    ("xcb-keysyms", "libxcb-keysyms1"),
    ("xcb-image", "libxcb-image0"),
    ("xcb-render-util", "libxcb-render-util0"),
    ("xcb-xinerama", "libxcb-xinerama0"),
    ("xcb-randr", "libxcb-randr0"),
    ("xcb-shape", "libxcb-shape0"),
    ("xcb-xkb", "libxcb-xkb1"),
)
"""(library name as ``ld`` knows it, Debian/Ubuntu package) for each library the xcb plugin needs."""


def _ldconfig_names() -> str:
    try:
        return subprocess.run(["ldconfig", "-p"], capture_output=True, text=True, timeout=5).stdout
    except (OSError, subprocess.SubprocessError):
        return ""


def missing_xcb_libraries(find=ctypes.util.find_library, ldconfig=_ldconfig_names) -> list[tuple[str, str]]:
    """The (library, package) pairs of :data:`XCB_LIBRARIES` that neither ``find`` (``ctypes.util.find_library``)
    nor the loader's cache (``ldconfig -p``) knows."""
    listed = None
    missing = []
    for name, package in XCB_LIBRARIES:
        if find(name):
            continue
        listed = ldconfig() if listed is None else listed
        if f"lib{name}.so" not in listed:
            missing.append((name, package))
    return missing


def uses_xcb(environ=os.environ, platform: str = sys.platform) -> bool:
    """Whether Qt will load the xcb plugin: on Linux with ``QT_QPA_PLATFORM`` unset or ``xcb``, except in a
    Wayland session without an X display."""
    if not platform.startswith("linux"):
        return False
    chosen = environ.get("QT_QPA_PLATFORM", "").split(":")[0].strip()
    if chosen:
        return chosen == "xcb"
    return bool(environ.get("DISPLAY")) or not environ.get("WAYLAND_DISPLAY")


def xcb_problem(environ=os.environ, platform: str = sys.platform, find=ctypes.util.find_library,
                ldconfig=_ldconfig_names) -> str | None:
    """One line naming the missing libraries and the packages to install, or None when nothing is missing."""
    if not uses_xcb(environ, platform):
        return None
    missing = missing_xcb_libraries(find, ldconfig)
    if not missing:
        return None
    names = ", ".join(f"lib{name}" for name, _ in missing)
    packages = " ".join(package for _, package in missing)
    return (f"the Qt X11 (xcb) platform plugin needs {names}, which this system lacks: install it with "
            f"`sudo apt-get install {packages}` (or run headless with QT_QPA_PLATFORM=offscreen)")
