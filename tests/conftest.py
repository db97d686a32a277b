"""Shared test set-up: headless Qt everywhere, numba kernels compiled once before the workers start."""
import gc
import os
import tempfile

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")
# the simulated bench's print releases (`labapp.acquisition.worldcache`) are cached for this test session only,
# never in the user's own cache; set here, in the controlling process, so that the workers and every `sfr`
# they start share it
os.environ.setdefault("SFR_CACHE", tempfile.mkdtemp(prefix="sfr-cache-"))


def _test_operator() -> None:
    """Every test (and every `sfr` subprocess it starts) acts as the operator "tester" of a users file of its
    own: recording needs a named operator. Tests of the operator checks set their own."""
    import tempfile

    from labapp.records.operators import OperatorError, add_user, load_users

    users = os.environ.setdefault("SFR_USERS", os.path.join(tempfile.mkdtemp(prefix="sfr-users-"), "users.json"))
    os.environ.setdefault("SFR_OPERATOR", "tester")
    try:
        if "tester" not in load_users():
            add_user("tester", "tester-password", users)
    except OperatorError:
        pass


_test_operator()


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
