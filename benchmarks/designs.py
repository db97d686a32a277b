"""A design of a source mesh judged by its print: the harness that design benchmarks and studies share.

`source_problem` makes `sfr design`'s problem for a mesh with the source's reference release as its target (what a
mesh target is by default), `judge` scores design variables by the print's true fit, and `NoStore` and
`MemoryRounds` stand in for a run folder's checkpoint store and rounds file, so that an optimisation runs in memory.
"""
from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks import untuned_shapes

__all__ = ["MemoryRounds", "NoStore", "judge", "source_problem", "warm_up"]


class NoStore:
    """A checkpoint store that keeps nothing."""

    def save(self, checkpoint, *, wait=True):
        pass

    def wait(self):
        pass


class MemoryRounds:
    """The correction rounds' state, kept in memory: ``states`` holds every state saved, in order."""

    def __init__(self):
        self.states = []

    def load(self):
        return self.states[-1] if self.states else None

    def save(self, state):
        self.states.append(state)


def _physical(problem, mesh):
    """The problem with the source's reference release as its target (what a mesh target is by default)."""
    from design.forward.reference import reference_release
    from design.inverse.targets import Target

    target = problem.target
    curve = reference_release(mesh, target.tau_mm).released_mm3
    return replace(problem, target=Target(target.tau_mm, curve, target.source))


def judge(objective, problem, x) -> tuple[float, float, int]:
    """(true fit, design-grid fit, pieces) of design variables ``x``: the print by the reference evaluator at its
    default lattice, the density's release on the design grid, both against the problem's (physical) target."""
    from design.fabrication.extract import count_pieces, revoxelize
    from design.forward.reference import reference_release
    from design.forward.simulator import simulate
    from design.inverse.defect import printed_mesh
    from design.inverse.objective import rel_rmse

    target, space = problem.target, objective.space
    grid = simulate(objective.density(x), space.dx_mm, mirror=space.mirror, total_time_mm=target.total_time_mm,
                    dtau_mm=target.total_time_mm / (target.tau_mm.size - 1)).released_mm3
    mesh = printed_mesh(objective, problem, x)
    if mesh is None:
        return np.inf, rel_rmse(grid, target.released_mm3), 0
    printed = reference_release(mesh, target.tau_mm).released_mm3
    pieces = count_pieces(revoxelize(mesh, space.dx_mm, problem.origin_mm, problem.full_shape))
    return rel_rmse(printed, target.released_mm3), rel_rmse(grid, target.released_mm3), pieces


def source_problem(name: str, mesh, config):
    """`sfr design`'s problem for ``mesh`` (written as ``NAME.stl``) under ``config``, its target the reference release."""
    from design.files.targets_io import load_problem

    with tempfile.TemporaryDirectory() as tmp:
        stl = Path(tmp) / f"{name}.stl"
        mesh.export(stl)
        return _physical(load_problem(replace(config, target=str(stl))), mesh)


def warm_up() -> None:
    """A tiny design and reference release, so that no timing includes compiling the kernels."""
    from design.forward.reference import reference_release
    from design.inverse.config import DesignConfig
    from design.inverse.optimize import build_objective, optimise
    from design.inverse.problem import prepare

    config = DesignConfig(target="sphere", resolution=16, max_iter=3)
    problem = prepare(config)
    optimise(build_objective(problem, config), problem, config, NoStore())
    reference_release(untuned_shapes.source("rock"), problem.target.tau_mm, cells=16)
