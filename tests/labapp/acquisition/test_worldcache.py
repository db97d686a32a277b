"""The simulated bench's print releases are computed once per mesh, physics and method, and kept on disk."""
import logging
import os

import numpy as np
import pytest
import trimesh

from labapp.acquisition import worldcache
from labapp.acquisition.printworld import PrintPhysics

RESOLUTION = 24


@pytest.fixture
def counted(monkeypatch, tmp_path):
    """The cache in ``tmp_path``, and the list of the computations it asked for."""
    monkeypatch.setenv("SFR_CACHE", str(tmp_path / "cache"))
    calls = []
    compute = worldcache.world_release

    def counting(mesh, physics, **kwargs):
        calls.append(physics)
        return compute(mesh, physics, **kwargs)
    monkeypatch.setattr(worldcache, "world_release", counting)
    return calls


def _release(mesh, physics):
    return worldcache.cached_world_release(mesh, physics, resolution=RESOLUTION, samples=41)


def test_a_release_is_computed_once_and_read_back_identical(counted, tmp_path):
    box = trimesh.creation.box((2.0, 3.0, 1.0))
    first = _release(box, PrintPhysics(anisotropy=1.3))
    again = _release(box.copy(), PrintPhysics(anisotropy=1.3))
    assert len(counted) == 1 and len(list((tmp_path / "cache" / "world").glob("*.npz"))) == 1
    assert np.array_equal(first.released_mm3, again.released_mm3) and np.array_equal(first.tau_mm, again.tau_mm)
    assert (first.volume_mm3, first.voxel_mm) == (again.volume_mm3, again.voxel_mm)
    _release(box, PrintPhysics(anisotropy=1.2))                          # other physics: computed
    _release(trimesh.creation.box((2.0, 3.0, 1.1)), PrintPhysics(anisotropy=1.3))   # another mesh: computed
    assert len(counted) == 3
    assert not list((tmp_path / "cache" / "world").glob(".tmp-*"))       # nothing left half-written


def test_a_torn_file_is_computed_again_and_an_unwritable_cache_is_skipped(counted, tmp_path, caplog):
    box = trimesh.creation.box((2.0, 2.0, 1.0))
    truth = _release(box, PrintPhysics())
    (stored,) = (tmp_path / "cache" / "world").glob("*.npz")
    stored.write_bytes(stored.read_bytes()[:100])                        # a power cut mid-copy, say
    with caplog.at_level(logging.WARNING):
        again = _release(box, PrintPhysics())
    assert "does not read" in caplog.text and len(counted) == 2
    assert np.array_equal(truth.released_mm3, again.released_mm3)
    assert np.array_equal(_release(box, PrintPhysics()).released_mm3, truth.released_mm3) and len(counted) == 2

    (tmp_path / "a-file").write_text("")
    os.environ["SFR_CACHE"] = str(tmp_path / "a-file")          # no folder can be made there (restored by monkeypatch)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        assert np.array_equal(_release(box, PrintPhysics()).released_mm3, truth.released_mm3)
    assert "not cached" in caplog.text


def test_the_cache_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("SFR_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert worldcache.cache_dir() == tmp_path / "xdg" / "shape-from-release"
    monkeypatch.setenv("SFR_CACHE", str(tmp_path / "own"))
    assert worldcache.cache_dir() == tmp_path / "own"
