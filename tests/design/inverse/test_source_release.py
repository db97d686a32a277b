"""A reference release is computed once per process for the same mesh, tau grid and settings."""
import numpy as np

import design.inverse.release_cache as cache
from design.geometry.shapes import sample_shape
from design.inverse.problem import source_release
from design.inverse.release_cache import cached_reference_release


def test_the_same_source_is_released_once_and_another_grid_again(monkeypatch):
    calls = []
    real = cache.reference_release
    monkeypatch.setattr(cache, "reference_release", lambda *a, **k: calls.append(k["cells"]) or real(*a, **k))
    monkeypatch.setattr(cache, "_kept", {})
    mesh, tau = sample_shape("sphere"), np.linspace(0.0, 8.0, 11)
    first = source_release(mesh, tau, 24)
    assert source_release(sample_shape("sphere"), tau.copy(), 24) is first and calls == [24]
    source_release(mesh, tau * 1.01, 24)
    source_release(mesh, tau, 32)
    assert calls == [24, 24, 32]
    # another setting is another release; the same ones, the kept one
    assert cached_reference_release(mesh, tau, cells=24, anisotropy=0.8) is not first and calls[-1] == 24
    assert cached_reference_release(mesh, tau, cells=24) is first and len(calls) == 4
    moved = mesh.copy()
    moved.apply_translation([0.5, 0.0, 0.0])
    cached_reference_release(moved, tau, cells=24)
    assert len(calls) == 5
