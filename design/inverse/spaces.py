"""Design spaces: how the optimisation variables become the simulated density grid.

A design space owns the variable field ``rho_hat`` (what nlopt sees), the grid on which the
filters of eq. (4) act, and the linear map from the filtered field to the reduced
(mirror-symmetric) simulation grid, with its adjoint. Spaces are built by name (`SPACE_CHOICES`,
`build_space`); "ico" carries the incremental-compliance term of section 3.6 (`design.fabrication.ico`)
as its ``fab_term``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from design.errors import DesignError
from design.fabrication.ico import IcoConfig, IcoTerm, layer_tops

BUILD_AXIS = 2
"""Array axis of the print's build direction (mesh z); extrusion replicates along it."""


class FabTerm(Protocol):
    """A fabrication term J_fab of eq. (4), evaluated on the reduced simulation grid.

    ``__call__(rho)`` returns the value and its gradient with respect to ``rho`` (same shape);
    ``normalise_at(rho)`` fixes the value that divides it (the start design's), ``seconds`` is the
    time spent in it so far; ``state()`` and ``restore(state)`` carry what a resumed run needs (warm
    starts, counters) through a checkpoint. `design.fabrication.ico.IcoTerm` (section 3.6) implements it.
    """

    name: str
    seconds: float

    def __call__(self, rho: np.ndarray) -> tuple[float, np.ndarray]: ...

    def normalise_at(self, rho: np.ndarray) -> float: ...

    def state(self) -> dict[str, np.ndarray]: ...

    def restore(self, state: dict[str, np.ndarray]) -> None: ...


@dataclass(frozen=True)
class SpaceRequest:
    """What every design space is built from.

    Parameters
    ----------
    full_shape : tuple of 3 int
        Voxels of the full (unreduced) design domain per axis; even along mirrored axes.
    dx_mm : float
        Voxel edge length, mm.
    height_vox : int or None
        Extrusion height h in voxels (extruded spaces only; None = the full domain height).
    ico : IcoConfig
        Settings of the incremental-compliance term (ico space only).
    """

    full_shape: tuple[int, int, int]
    dx_mm: float
    height_vox: int | None = None
    ico: IcoConfig = IcoConfig()

    def __post_init__(self) -> None:
        if len(self.full_shape) != 3 or min(self.full_shape) < 2:
            raise DesignError(f"design domain must be 3D with >= 2 voxels per axis, got {self.full_shape}")
        if not self.dx_mm > 0:
            raise DesignError(f"voxel size must be > 0 mm, got {self.dx_mm}")
        if self.height_vox is not None and not 1 <= self.height_vox <= self.full_shape[BUILD_AXIS]:
            raise DesignError(f"extrusion height must be in [1, {self.full_shape[BUILD_AXIS]}] voxels, "
                              f"got {self.height_vox}")


@dataclass(frozen=True)
class DesignSpace:
    """Variables -> reduced simulation grid, a linear map with an exact adjoint.

    Attributes
    ----------
    name : str
    var_shape : tuple of int
        Shape of the design variables (also the grid the filters act on).
    var_mirror : tuple of bool
        Mirror planes of the variable grid (at index 0 of each flagged axis).
    grid_shape : tuple of 3 int
        Shape of the reduced simulation grid.
    mirror : tuple of 3 bool
        Mirror planes of the simulation grid (passed to `design.forward.simulator.simulate`).
    dx_mm : float
    fab_term : FabTerm or None
        J_fab of eq. (4) for this space, None when the space has no fabrication term.
    """

    name: str
    var_shape: tuple[int, ...]
    var_mirror: tuple[bool, ...]
    grid_shape: tuple[int, int, int]
    mirror: tuple[bool, bool, bool]
    dx_mm: float
    fab_term: FabTerm | None = None

    @property
    def multiplicity(self) -> int:
        """How many copies of the reduced grid make the full object."""
        return 2 ** sum(self.mirror)

    @property
    def extruded(self) -> bool:
        return len(self.var_shape) == 2

    def to_grid(self, rho_var: np.ndarray) -> np.ndarray:
        """The reduced simulation density from the filtered variable field.

        For a 2D space the field is replicated over the extrusion height (section 3.6).
        """
        if not self.extruded:
            return rho_var
        return np.repeat(np.expand_dims(rho_var, BUILD_AXIS), self.grid_shape[BUILD_AXIS], axis=BUILD_AXIS)

    def to_grid_adjoint(self, g_grid: np.ndarray) -> np.ndarray:
        """Adjoint of `to_grid`: sums the 3D gradient over the extrusion height."""
        if not self.extruded:
            return g_grid
        return g_grid.sum(axis=BUILD_AXIS)

    def unfold(self, grid: np.ndarray) -> np.ndarray:
        """The full object from the reduced grid: ``concatenate([flip(half), half])`` per mirror axis."""
        for ax, mir in enumerate(self.mirror):
            if mir:
                grid = np.concatenate([np.flip(grid, axis=ax), grid], axis=ax)
        return grid


def _halve(full_shape: tuple[int, ...], mirror: tuple[bool, ...]) -> tuple[int, ...]:
    bad = [n for n, m in zip(full_shape, mirror) if m and n % 2]
    if bad:
        raise DesignError(f"mirrored axes need an even voxel count, got {full_shape} with mirror {mirror}")
    return tuple(n // 2 if m else n for n, m in zip(full_shape, mirror))


def nfc_space(request: SpaceRequest) -> DesignSpace:
    """Free 3D design, no fabrication constraint, octant symmetry (section 5.2)."""
    mirror = (True, True, True)
    shape = _halve(request.full_shape, mirror)
    return DesignSpace("nfc", shape, mirror, shape, mirror, request.dx_mm)


def extruded_space(request: SpaceRequest) -> DesignSpace:
    """A 2D density extruded over h voxels along the build axis, quadrant symmetry (section 3.6)."""
    mirror = tuple(ax != BUILD_AXIS for ax in range(3))
    height = request.height_vox or request.full_shape[BUILD_AXIS]
    grid = list(_halve(request.full_shape, mirror))
    grid[BUILD_AXIS] = height
    var_shape = tuple(n for ax, n in enumerate(grid) if ax != BUILD_AXIS)
    return DesignSpace("extruded", var_shape, (True, True), tuple(grid), mirror, request.dx_mm)


def ico_space(request: SpaceRequest) -> DesignSpace:
    """Free 3D design with the incremental-compliance term J_fab (section 3.6), quadrant symmetry.

    The build direction is +z (`BUILD_AXIS`), z = 0 the build plate; x and y are mirrored (section 5.2).
    """
    mirror = tuple(ax != BUILD_AXIS for ax in range(3))
    shape = _halve(request.full_shape, mirror)
    layer_tops(-(-shape[BUILD_AXIS] // request.ico.coarsen), request.ico.layers)  # enough elements per layer
    term = IcoTerm(request.dx_mm, request.ico, mirror=(mirror[0], mirror[1]))
    return DesignSpace("ico", shape, mirror, shape, mirror, request.dx_mm, fab_term=term)


SpaceBuilder = Callable[[SpaceRequest], DesignSpace]
_BUILDERS: dict[str, SpaceBuilder] = {"nfc": nfc_space, "extruded": extruded_space, "ico": ico_space}
SPACE_CHOICES: tuple[str, ...] = tuple(_BUILDERS)
"""The design spaces' names (`DesignConfig.space`, ``sfr design --space``)."""


def available_spaces() -> tuple[str, ...]:
    """Names of the design spaces, sorted."""
    return tuple(sorted(_BUILDERS))


def build_space(name: str, request: SpaceRequest) -> DesignSpace:
    """Build the named design space.

    Raises
    ------
    DesignError
        If the name is unknown.
    """
    if name in _BUILDERS:
        return _BUILDERS[name](request)
    raise DesignError(f"unknown design space {name!r}; available: {', '.join(available_spaces())}")
