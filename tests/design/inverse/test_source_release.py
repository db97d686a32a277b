"""A source's reference release is computed once per process for the same mesh, tau grid and lattice."""
import numpy as np

import design.inverse.problem as problem_module
from design.geometry.shapes import sample_shape
from design.inverse.problem import source_release


def test_the_same_source_is_released_once_and_another_grid_again(monkeypatch):
    calls = []
    real = problem_module.reference_release
    monkeypatch.setattr(problem_module, "reference_release", lambda *a, **k: calls.append(k["cells"]) or real(*a, **k))
    monkeypatch.setattr(problem_module, "_source_releases", {})
    mesh, tau = sample_shape("sphere"), np.linspace(0.0, 8.0, 11)
    first = source_release(mesh, tau, 24)
    assert source_release(sample_shape("sphere"), tau.copy(), 24) is first and calls == [24]
    source_release(mesh, tau * 1.01, 24)
    source_release(mesh, tau, 32)
    assert calls == [24, 24, 32]
