"""Shared test set-up: a hermetic environment, headless Qt everywhere, numba kernels compiled once before the
workers start."""
import atexit
import gc
import os
import shutil
import tempfile
from pathlib import Path

import pytest

HOME_VARIABLES = ("HOME", "XDG_CONFIG_HOME", "XDG_CACHE_HOME", "XDG_DATA_HOME", "XDG_STATE_HOME", "XDG_RUNTIME_DIR")
"""The user's home and its XDG folders: every test, and every `sfr` it starts, gets the session's own."""
FOREIGN_PREFIXES = ("SFR_", "DASK_")
"""The product's variables and Dask's configuration: none of the shell's values reach a test."""
SUITE_SWITCHES = ("SFR_FIGURES",)
"""Variables of the test suite itself, kept from the shell (``SFR_FIGURES=1`` refreshes the docs' pictures)."""
FOREIGN_VARIABLES = ("VCAMERADIR",)
"""Other variables the drivers read (the virtual camera's folder): set only by the tests that use them."""
TEST_OPERATOR, TEST_PASSWORD = "tester", "tester-password"


def _hermetic_environment() -> None:
    """Replace the shell's home, XDG folders and product variables by a temporary home made for this test
    session, in the controlling process (an xdist worker inherits the controller's environment). Every test,
    and every `sfr` subprocess it starts, acts as the operator "tester" of the session's users file (the
    regulated lab: operators enforced; tests of the operator checks set their own, and the `no_users_file`
    fixture gives the research lab, without a users file) and caches the simulated bench's print releases
    (`labapp.acquisition.worldcache`) in the session's cache."""
    os.environ["QT_QPA_PLATFORM"] = "offscreen"
    os.environ["MPLBACKEND"] = "Agg"
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return
    for name in list(os.environ):
        if (name.startswith(FOREIGN_PREFIXES) and name not in SUITE_SWITCHES) or name in FOREIGN_VARIABLES:
            del os.environ[name]
    root = Path(tempfile.mkdtemp(prefix="sfr-tests-"))
    home = root / "home"
    folders = {"HOME": home, "XDG_CONFIG_HOME": home / ".config", "XDG_CACHE_HOME": home / ".cache",
               "XDG_DATA_HOME": home / ".local" / "share", "XDG_STATE_HOME": home / ".local" / "state",
               "XDG_RUNTIME_DIR": root / "runtime"}
    for name, folder in folders.items():
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        os.environ[name] = str(folder)
    os.environ["SFR_CACHE"] = str(root / "sfr-cache")
    os.environ["SFR_USERS"] = str(root / "users.json")
    os.environ["SFR_OPERATOR"] = TEST_OPERATOR

    from labapp.records.operators import add_user

    add_user(TEST_OPERATOR, TEST_PASSWORD)
    atexit.register(_remove_session_home, root, os.getpid())


def _remove_session_home(root: Path, pid: int) -> None:
    """At the controlling process's exit (after every worker's), remove the session's home."""
    if os.getpid() == pid:
        shutil.rmtree(root, ignore_errors=True)


_hermetic_environment()
SESSION_ENVIRONMENT = {name: value for name, value in os.environ.items()
                       if name in HOME_VARIABLES or name.startswith(FOREIGN_PREFIXES)}
"""The environment every test starts from (restored before each test: a test or the code it runs may set
`SFR_OPERATOR` and the like)."""


@pytest.fixture
def no_users_file(tmp_path, monkeypatch):
    """A lab without a users file (operators not enforced) and no `SFR_OPERATOR`: actions are recorded under the
    login name, unverified. Returns the users file's path (absent)."""
    path = tmp_path / "no-users" / "users.json"
    monkeypatch.setenv("SFR_USERS", str(path))
    monkeypatch.delenv("SFR_OPERATOR", raising=False)
    return path


@pytest.fixture(autouse=True)
def _session_environment(monkeypatch):
    """Each test starts from the session's environment, whatever an earlier test left in `os.environ`."""
    for name in list(os.environ):
        if (name.startswith(FOREIGN_PREFIXES) or name in FOREIGN_VARIABLES) and name not in SESSION_ENVIRONMENT:
            monkeypatch.delenv(name)
    for name, value in SESSION_ENVIRONMENT.items():
        monkeypatch.setenv(name, value)


def pytest_configure(config):
    """In the controlling process only: fill numba's on-disk cache, so that parallel workers and the
    `sfr` subprocesses the tests start load compiled kernels instead of compiling (and writing the
    cache) concurrently."""
    if hasattr(config, "workerinput"):
        return
    import numpy as np

    from design import release_gradient, sample_shape, simulate_mesh

    for symmetry in ("", "xyz"):
        release = simulate_mesh(sample_shape("sphere"), resolution=8, symmetry=symmetry)
        release_gradient(release, np.ones_like(release.released_mm3))


@pytest.fixture(autouse=True)
def _qt_garbage_in_the_gui_thread(request):
    """In Qt tests, Python's cyclic garbage collector runs only here, in the GUI thread, as the
    application's `labapp.gui.app.gui_thread_garbage_collector` arranges: a Qt object collected on
    another thread (a Dask or background-task thread) can deadlock PySide in its destructor."""
    if "qtbot" not in request.fixturenames:
        yield
        return
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()
        gc.collect()


@pytest.fixture
def two_boxes_stl(tmp_path):
    """An STL of two separate 4 mm cubes 4 mm apart: a source that is itself two pieces."""
    import trimesh

    boxes = [trimesh.creation.box(extents=(4.0, 4.0, 4.0)).apply_translation([x, 0.0, 0.0]) for x in (-4.0, 4.0)]
    path = tmp_path / "two_boxes.stl"
    trimesh.util.concatenate(boxes).export(path)
    return path
