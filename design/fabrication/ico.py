"""The incremental-compliance fabrication term J_fab of section 3.6 and its gradient.

The design is cut along the build direction (+z, array axis 2) into L layers. Partial design l
holds layers 1..l and nothing above them; it stands on the build plate (z = 0, clamped) and
carries its own weight, a body force along -z proportional to rho. With ``K_l(rho) u_l = f_l(rho)``

    J_fab = 1/(2L) sum_l f_l . u_l                                                  (section 3.6)
    dJ_fab/drho = 1/L sum_l [ (df_l/drho) . u_l - 1/2 u_l^T (dK_l/drho) u_l ]     (section 3.6)

(compliance is self-adjoint: no adjoint solve). Elasticity (`design.fabrication.elasticity`) runs on the
design grid coarsened by `IcoConfig.coarsen` per axis: an element's modulus is the mean of its
voxels' E(rho) and its load the mean of their rho. The grid is padded with void up to a multiple
of the factor. Quadrant symmetry: the reduced grid's index-0 faces in x and y are mirror planes.

Units: E0 = 1 and unit specific weight, lengths in mm; `IcoTerm` divides by the value at the start
design, so J_fab = 1 there at every resolution and domain size and w_f keeps its meaning.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from design.errors import DesignError
from design.fabrication.deflation import island_deflation
from design.fabrication.elasticity import (
    E_MIN_RATIO,
    LAWS,
    POISSON_RATIO,
    element_energy,
    modulus,
    self_weight,
    self_weight_adjoint,
)
from design.fabrication.multigrid import PCG_TOL, Scratch, hierarchy, pcg
from design.threads import thread_count

log = logging.getLogger(__name__)

DEFAULT_LAYERS = 8
"""L, the number of partial designs (section 5.2)."""
DEFAULT_COARSEN = 2
"""Voxels per elasticity element edge; the error it causes in J_fab and its gradient:
docs/benchmarks.md#incremental-compliance-term."""
MAX_LAYERS, MAX_COARSEN = 256, 8
"""The most partial designs and voxels per elasticity element edge `IcoConfig` takes."""


@dataclass(frozen=True)
class IcoConfig:
    """Settings of the incremental-compliance term.

    Parameters
    ----------
    layers : int
        L >= 1 partial designs.
    coarsen : int
        Design voxels per element edge (1 = elasticity on the design grid).
    law : str
        "simp" (p = 3, section 3.6) or "ramp" (q = 3).
    poisson : float
        Poisson's ratio.
    e_min : float
        Void modulus E_min / E0.
    tol : float
        PCG relative residual.
    warm_start : bool
        Start each layer's solve from its solution at the previous evaluation.
    deflate : bool
        Deflate the near-rigid modes of floating solid islands in PCG (`design.fabrication.deflation`).
    """

    layers: int = DEFAULT_LAYERS
    coarsen: int = DEFAULT_COARSEN
    law: str = "simp"
    poisson: float = POISSON_RATIO
    e_min: float = E_MIN_RATIO
    tol: float = PCG_TOL
    warm_start: bool = True
    deflate: bool = True

    def __post_init__(self) -> None:
        if not 1 <= self.layers <= MAX_LAYERS or not 1 <= self.coarsen <= MAX_COARSEN:
            raise DesignError(f"ICO needs layers in [1, {MAX_LAYERS}] and coarsen in [1, {MAX_COARSEN}]; got {self.layers}, "
                              f"{self.coarsen}")
        if self.law not in LAWS:
            raise DesignError(f"stiffness law must be one of {LAWS}, got {self.law!r}")
        if not 0 < self.e_min < 1 or not 0 < self.tol < 1 or not -1 < self.poisson < 0.5:
            raise DesignError(f"need 0 < e_min < 1, 0 < tol < 1, -1 < poisson < 0.5; got {self.e_min}, "
                              f"{self.tol}, {self.poisson}")


@dataclass(frozen=True)
class IcoResult:
    """One evaluation of J_fab (unnormalised).

    Attributes
    ----------
    value : float
        J_fab = 1/(2L) sum_l f_l . u_l (E0 = 1, unit specific weight, mm).
    grad : ndarray of float, shape of rho
        dJ_fab/drho.
    compliances : (L,) ndarray of float
        f_l . u_l per partial design.
    iterations : (L,) ndarray of int
        PCG iterations per layer.
    seconds : float
    """

    value: float
    grad: np.ndarray
    compliances: np.ndarray
    iterations: np.ndarray
    seconds: float


def layer_tops(nz: int, layers: int) -> list[int]:
    """Element rows held by each partial design: ``round(l nz / L)``, l = 1..L."""
    if layers > nz:
        raise DesignError(f"{layers} layers need at least as many elasticity elements along z, got {nz}; "
                          f"use fewer layers or a finer grid")
    return [int(round(l * nz / layers)) for l in range(1, layers + 1)]


def _blocks(a: np.ndarray, c: int) -> np.ndarray:
    """(Z, Y, X) voxels -> (Z/c, Y/c, X/c) block means."""
    z, y, x = a.shape
    return a.reshape(z // c, c, y // c, c, x // c, c).mean(axis=(1, 3, 5))


@dataclass(frozen=True)
class _Elements:
    """The elasticity grid of a density: blocks of ``coarsen``^3 voxels, (z, y, x) order.

    Attributes
    ----------
    e_mod : (Z, Y, X) ndarray of float
        Element moduli, the mean of their voxels' E(rho).
    load : (Z, Y, X) ndarray of float
        Element loads, the mean of their voxels' rho.
    de_vox : (cZ, cY, cX) ndarray of float
        dE/drho per voxel of the padded grid.
    h : (float, float, float)
        Element edges, mm.
    coarsen : int
    """

    e_mod: np.ndarray
    load: np.ndarray
    de_vox: np.ndarray
    h: tuple[float, float, float]
    coarsen: int

    @property
    def volume(self) -> float:
        """Element volume, mm^3."""
        return self.h[0] ** 3


def _elements(rho: np.ndarray, dx_mm: float, config: IcoConfig) -> _Elements:
    """The elasticity grid of an (X, Y, Z) density, padded with void up to a multiple of ``config.coarsen``."""
    c = config.coarsen
    zyx = np.ascontiguousarray(np.asarray(rho, dtype=float).transpose(2, 1, 0))
    pad = [(0, -n % c) for n in zyx.shape]
    zyx = np.pad(zyx, pad)  # void beyond the far faces and above the top
    e_vox, de_vox = modulus(zyx, config.law, config.e_min)
    return _Elements(_blocks(e_vox, c), _blocks(zyx, c), de_vox, (c * dx_mm,) * 3, c)


_Solved = tuple[np.ndarray, int, np.ndarray]
"""One partial design's displacements, PCG iterations and element energies at unit modulus."""


def _solve_layer(grid: _Elements, top: int, force: np.ndarray, u0: np.ndarray | None, config: IcoConfig,
                 mirror: tuple[bool, bool], scratch: Scratch) -> _Solved:
    """The partial design of the element rows below ``top`` under its own weight ``force``, from ``u0``."""
    levels = hierarchy(grid.e_mod[:top], grid.h, config.poisson, *mirror, scratch=scratch)
    fine = levels[0]
    deflation = island_deflation(fine.e_mod, grid.h, fine.s, fine.free) if config.deflate else None
    u, its = pcg(levels, force, u0, config.tol, deflation=deflation)
    energy = np.empty((top,) + grid.e_mod.shape[1:])
    element_energy(levels[0].ke, u, energy)
    return u, its, energy


def _solve_concurrently(solve: Callable[[int, np.ndarray | None, Scratch], _Solved], tops: list[int],
                        warm: list[np.ndarray], memories: list[Scratch]) -> list[_Solved]:
    """Every layer from its warm start, independently: one thread per core, each with its share of the layers,
    largest first (the kernels release the GIL)."""
    queues: list[list[int]] = [[] for _ in range(min(len(tops), thread_count()))]
    for l in np.argsort(tops, kind="stable")[::-1]:
        min(queues, key=lambda q: sum(tops[i] for i in q)).append(int(l))

    def run(queue: list[int], memory: Scratch) -> list[tuple[int, _Solved]]:
        return [(l, solve(l, warm[l], memory)) for l in queue]

    with ThreadPoolExecutor(len(queues)) as pool:
        done = dict(pair for part in pool.map(run, queues, memories[:len(queues)]) for pair in part)
    return [done[l] for l in range(len(tops))]


def _solve_in_sequence(solve: Callable[[int, np.ndarray | None, Scratch], _Solved], tops: list[int],
                       memory: Scratch) -> list[_Solved]:
    """Every layer in turn, each from the solution of the layer below, its top row continued upward."""
    results: list[_Solved] = []
    for l, top in enumerate(tops):
        prev = results[-1][0] if results else None
        u0 = None if prev is None else np.concatenate([prev, np.repeat(prev[-1:], top + 1 - prev.shape[0], axis=0)])
        results.append(solve(l, u0, memory))
    return results


def incremental_compliance(rho: np.ndarray, dx_mm: float, config: IcoConfig = IcoConfig(), *,
                           mirror: tuple[bool, bool] = (True, True),
                           warm: list[np.ndarray] | None = None,
                           scratch: list[Scratch] | None = None) -> tuple[IcoResult, list[np.ndarray]]:
    """J_fab and its gradient for a reduced density grid.

    Parameters
    ----------
    rho : (X, Y, Z) ndarray of float in [0, 1]
        Density, array axis 2 the build direction, z = 0 on the build plate.
    dx_mm : float
        Voxel edge, mm.
    config : IcoConfig
    mirror : (bool, bool)
        Mirror planes at the index-0 faces of x and y.
    warm : list of ndarrays, optional
        Per-layer solutions of a previous call on the same grid (initial guesses). With them the
        layers are independent and solved concurrently, one thread per core; without them in
        sequence, each from the solution of the layer below.
    scratch : list of Scratch, optional
        Memory for the solver, one per thread, kept from earlier calls (fresh memory costs page faults).

    Returns
    -------
    IcoResult
    solutions : list of (nz_l + 1, ny + 1, nx + 1, 3) ndarrays
        Per-layer displacements (z, y, x order), for the next call's ``warm``.
    """
    t0 = time.perf_counter()
    grid = _elements(rho, dx_mm, config)
    tops = layer_tops(grid.e_mod.shape[0], config.layers)
    forces = [self_weight(grid.load[:top], grid.volume) for top in tops]
    memories = list(scratch or []) + [Scratch() for _ in range(len(tops) - len(scratch or []))]

    def solve(l: int, u0: np.ndarray | None, memory: Scratch) -> _Solved:
        return _solve_layer(grid, tops[l], forces[l], u0, config, mirror, memory)

    if warm is not None and [w.shape for w in warm] == [f.shape for f in forces]:
        results = _solve_concurrently(solve, tops, warm, memories)
    else:
        results = _solve_in_sequence(solve, tops, memories[0])
    compliances = np.array([float(np.vdot(f, u)) for f, (u, _, _) in zip(forces, results)])
    iterations = np.array([its for _, its, _ in results], dtype=int)
    value = compliances.sum() / (2.0 * len(tops))
    grad = _gradient(grid, tops, results, rho.shape)
    return IcoResult(value, grad, compliances, iterations, time.perf_counter() - t0), [u for u, _, _ in results]


def _gradient(grid: _Elements, tops: list[int], results: list[_Solved], shape: tuple[int, int, int]) -> np.ndarray:
    """dJ_fab/drho on the (X, Y, Z) voxels of a density of ``shape``, from each partial design's solution."""
    g_load, g_e = np.zeros_like(grid.load), np.zeros_like(grid.e_mod)
    for top, (u, _, energy) in zip(tops, results):  # summed in layer order: deterministic
        g_load[:top] += self_weight_adjoint(u, grid.load[:top].shape, grid.volume)
        g_e[:top] -= 0.5 * energy
    L, c = len(tops), grid.coarsen
    # chain to voxels: d(block mean)/d voxel = 1/c^3
    up = np.ones((c, c, c)) / c ** 3
    g_vox = np.kron(g_load / L, up) + np.kron(g_e / L, up) * grid.de_vox
    return np.ascontiguousarray(g_vox[:shape[2], :shape[1], :shape[0]].transpose(2, 1, 0))


class IcoTerm:
    """J_fab of section 3.6 as a design space's fabrication term, normalised by its start value.

    Keeps each layer's solution for the next evaluation's warm start, and for reports the time
    (``seconds``), the number of evaluations and the PCG iterations per layer summed over them.

    Parameters
    ----------
    dx_mm : float
        Voxel edge, mm.
    config : IcoConfig
    mirror : (bool, bool)
        Mirror planes of the reduced grid in x and y.
    """

    name = "ICO"

    def __init__(self, dx_mm: float, config: IcoConfig = IcoConfig(), mirror: tuple[bool, bool] = (True, True)):
        self.dx_mm = float(dx_mm)
        self.config = config
        self.mirror = mirror
        self.reference: float | None = None
        self.last: IcoResult | None = None
        self.seconds = 0.0
        self.evaluations = 0
        self.iterations = np.zeros(config.layers, dtype=int)
        self._warm: list[np.ndarray] | None = None
        self._scratch = [Scratch() for _ in range(min(config.layers, thread_count()))]

    def evaluate(self, rho: np.ndarray) -> IcoResult:
        """Unnormalised J_fab and gradient; updates the warm-start solutions and the timing."""
        warm = self._warm if self.config.warm_start else None
        result, self._warm = incremental_compliance(rho, self.dx_mm, self.config, mirror=self.mirror, warm=warm,
                                                    scratch=self._scratch)
        self.last = result
        self.seconds += result.seconds
        self.evaluations += 1
        self.iterations += result.iterations
        log.debug("ICO %.6g, PCG iterations %s, %.3f s", result.value, result.iterations.tolist(), result.seconds)
        return result

    def state(self) -> dict[str, np.ndarray]:
        """What a resumed run needs to continue as this one would: the warm-start solutions of the last
        evaluation (``warm_L`` per layer; they decide where each PCG solve starts, so its result to within
        the tolerance) and the counters (``evaluations``, ``iterations``, ``seconds``). The arrays are the
        term's own, not copies: an evaluation replaces them and never writes into them."""
        state = {"evaluations": np.array(self.evaluations), "iterations": self.iterations.copy(),
                 "seconds": np.array(self.seconds)}
        for l, u in enumerate(self._warm or ()):
            state[f"warm_{l}"] = u
        return state

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Continue from a `state` of a term with the same grid and configuration."""
        warm = [state[f"warm_{l}"] for l in range(self.config.layers) if f"warm_{l}" in state]
        self._warm = warm if len(warm) == self.config.layers else None
        self.evaluations = int(state["evaluations"])
        self.iterations = np.array(state["iterations"], dtype=int)
        self.seconds = float(state["seconds"])

    def normalise_at(self, rho: np.ndarray) -> float:
        """Set the reference (the start design's J_fab) that later values are divided by; returns it."""
        value = self.evaluate(rho).value
        if not value > 0:
            raise DesignError(f"the start design has no incremental compliance ({value}); it holds no material")
        self.reference = value
        return value

    def __call__(self, rho: np.ndarray) -> tuple[float, np.ndarray]:
        """J_fab / J_fab(start) and its gradient with respect to ``rho``."""
        if self.reference is None:
            raise DesignError("the ICO term has no reference value: call normalise_at(start density) first")
        result = self.evaluate(rho)
        return result.value / self.reference, result.grad / self.reference
