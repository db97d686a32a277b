"""J_chan: a differentiable measure of the open channels narrower than a minimum width.

A water-soluble print swells on wetting, and a channel narrower than the swelling width w stays shut
(`design.forward.swelling`); a design meant to print with open channels keeps every channel at least w wide.
This term measures, smoothly, the void that a morphological closing fills, so that the optimiser itself avoids
narrow channels. It is a term of the objective beyond the paper's eq. (4) (`design.inverse.objective`); the
outputs still fill any channel narrower than w that is left (`design.files.printed.close_narrow_channels`).

Structuring elements. The forward model and the fill call a void voxel part of a narrow channel when, along
one of the grid's axes, its run of void from solid to solid is shorter than w (`design.forward.swelling`).
The closing by a segment of ``L = ceil(w / dx)`` voxels along an axis fills exactly the runs of at most
``L - 1`` voxels, i.e. those shorter than w, so J_chan closes the density along each axis separately and
adds the three. (A ball of diameter w would miss what the fill shuts, a groove shallower than the ball's
radius, and would fill what it leaves alone, the concave corners of a wide chamber and the staircase of a
voxelised curved face.)

Smooth morphology. With W_a the mean over the segment ``i - L + 1 ... i`` along axis a, W'_a over
``i ... i + L - 1``, and b the sharpness `SHARPNESS`,

    D_a(u) = (1/b) log( W_a exp(b u) )       a soft maximum of u over the segment (dilation),
    E_a(v) = 1 - (1/b) log( W'_a exp(b (1 - v)) )   a soft minimum (erosion),
    C_a(rho) = E_a(D_a(rho))                 the closing: a void run shorter than L is filled.

D lies between the segment's mean and its maximum: 1 where it holds only solid, 0 where it holds only void,
and ``1 + log(f) / b`` where a share f of it is solid (at least 1/L), so a wall's dilation reaches along the
segment at nearly full strength. The measure is

    J_chan = sum_a sum_i max(C_a,i - rho_i, 0)^2 dV,

the narrow void's volume with each voxel weighted by the square of how far the closing fills it, once for
every axis along which it is narrow (a slot counts once, a pin-hole twice), in mm^3 with ``dV`` the voxel's
volume, so the value of one geometry does not depend on the resolution. A binary slot narrower than w costs
0.9 to 1 times its volume per axis; the soft minimum leaves a residue ``C - rho`` of at most ``log(L) / b``
on the void side of a face it closes no channel at, whose square is a few thousandths (`SHARPNESS`). A
uniform grey density is its own closing, so a grey design pays only where its density varies. For
``w <= dx`` (L = 1) no channel can be narrower than w and J_chan is 0.

Boundaries. A mirrored axis's low face (index 0, ``mirror`` of `design.forward.simulator.simulate`) reflects:
the grid continues into its mirror image, so a slot against the mirror plane counts by its full mirrored
width. Every other face is the bath, void that never ends: a run open to it is no channel.

Gradient. Exact by the chain rule: the adjoint of a segment mean is the mean over the reflected segment, and
the adjoint of the boundary padding folds the padded gradient back onto the voxels it copies.
"""
from __future__ import annotations

import numpy as np

from design._validate import check_mirror
from design.errors import DesignError

SHARPNESS = 30.0
"""b of the soft maximum and minimum (log-sum-exp, 1 / b their smoothing in density units). At 30 the residue
at a face is at most log(L) / 30 (0.04 for L = 3) against about 0.9 inside a narrow slot, and exp(b) = 1e13 keeps
the sums of positive terms well inside double precision."""


def segment_voxels(width_mm: float, dx_mm: float) -> int:
    """L: the closing's segment, voxels, ``ceil(width / dx)`` (a run of void is filled when shorter than width)."""
    return max(1, int(np.ceil(float(width_mm) / float(dx_mm) - 1e-9)))


def _shifted_sum(u: np.ndarray, axis: int, lo: int, hi: int) -> np.ndarray:
    """``out[i] = sum_{o = lo..hi} u[i + o]`` along ``axis``, zero beyond the array; its adjoint is the same
    with ``(-hi, -lo)``."""
    out = np.zeros_like(u)
    n = u.shape[axis]
    dst = [slice(None)] * u.ndim
    src = [slice(None)] * u.ndim
    for o in range(lo, hi + 1):
        if abs(o) >= n:
            continue
        dst[axis] = slice(max(0, -o), n - max(0, o))
        src[axis] = slice(max(0, o), n + min(0, o))
        out[tuple(dst)] += u[tuple(src)]
    return out


class NarrowVoids:
    """J_chan of densities on one grid (module docstring), with its gradient.

    Parameters
    ----------
    shape : tuple of 2 or 3 int
        The density grid (a half/quadrant/octant with `mirror`).
    dx_mm : float
        Voxel edge, mm.
    width_mm : float
        Minimum open channel width w, mm (> 0).
    mirror : tuple of bool, optional
        Per axis, a mirror plane at the index-0 face.
    sharpness : float
        b of the soft maximum (`SHARPNESS`).
    """

    def __init__(self, shape: tuple[int, ...], dx_mm: float, width_mm: float,
                 mirror: tuple[bool, ...] | None = None, sharpness: float = SHARPNESS) -> None:
        shape = tuple(int(n) for n in shape)
        if len(shape) not in (2, 3) or min(shape) < 1:
            raise DesignError(f"the channel-width term needs a 2D or 3D grid, got shape {shape}")
        if not (np.isfinite(dx_mm) and dx_mm > 0):
            raise DesignError(f"voxel edge must be a finite number > 0 mm, got {dx_mm}")
        if not (np.isfinite(width_mm) and width_mm > 0):
            raise DesignError(f"minimum channel width must be a finite number > 0 mm, got {width_mm}")
        if not (np.isfinite(sharpness) and 1.0 <= sharpness <= 200.0):
            raise DesignError(f"sharpness must be in [1, 200], got {sharpness}")
        self.shape = shape
        self.dx_mm = float(dx_mm)
        self.width_mm = float(width_mm)
        self.mirror = check_mirror(mirror, len(shape))
        self.sharpness = float(sharpness)
        self.segment = segment_voxels(width_mm, dx_mm)
        # padded by two segments: the dilation is exact one segment in, the erosion two (on the grid)
        self.pad = 2 * (self.segment - 1)
        self._crop = tuple(slice(self.pad, self.pad + n) for n in shape)

    def _padded(self, rho: np.ndarray) -> np.ndarray:
        """rho padded by `pad` voxels on every face: the bath (0) beyond every face, except the mirror image
        (index -1 - v the image of v) beyond a mirrored low face, up to the image's own far face."""
        out = np.pad(rho, self.pad)
        for axis, (n, mirrored) in enumerate(zip(self.shape, self.mirror)):
            if mirrored:
                out[self._image(axis, n)] = out[self._source(axis, n)]
        return out

    def _fold(self, grad: np.ndarray) -> np.ndarray:
        """Adjoint of `_padded`: the padded gradient folded back onto the voxels it copies (the images last
        copied, first folded)."""
        out = grad.copy()
        for axis in reversed(range(grad.ndim)):
            if self.mirror[axis]:
                out[self._source(axis, self.shape[axis])] += out[self._image(axis, self.shape[axis])]
        return out[self._crop]

    def _image(self, axis: int, n: int) -> tuple[slice, ...]:
        index = [slice(None)] * len(self.shape)
        index[axis] = slice(self.pad - min(self.pad, n), self.pad)
        return tuple(index)

    def _source(self, axis: int, n: int) -> tuple[slice, ...]:
        index = [slice(None)] * len(self.shape)
        index[axis] = slice(self.pad + min(self.pad, n) - 1, self.pad - 1, -1)
        return tuple(index)

    def _check(self, rho: np.ndarray) -> np.ndarray:
        rho = np.asarray(rho, dtype=float)
        if rho.shape != self.shape:
            raise DesignError(f"density of shape {rho.shape} given to a channel-width term of grid {self.shape}")
        return rho

    def closings(self, rho: np.ndarray) -> list[np.ndarray]:
        """The smooth closings C_a(rho) along each axis, on the grid (module docstring)."""
        rho = self._check(rho)
        e1 = np.exp(self.sharpness * self._padded(rho))
        return [self._closing(e1, axis)[0] for axis in range(rho.ndim)]

    def _closing(self, e1: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """C_a on the grid from ``e1 = exp(b u)`` of the padded density, with ``m1 = W_a e1``, ``e2 = exp(b (1 - D))``
        ``= e^b / m1`` and ``m2 = W'_a e2`` on the padded grid."""
        span = self.segment - 1
        m1 = _shifted_sum(e1, axis, -span, 0) / self.segment
        e2 = np.exp(self.sharpness) / m1
        m2 = _shifted_sum(e2, axis, 0, span) / self.segment
        return 1.0 - np.log(m2[self._crop]) / self.sharpness, m1, e2, m2

    def __call__(self, rho: np.ndarray, cell_mm3: float | None = None) -> tuple[float, np.ndarray]:
        """J_chan and dJ_chan/drho.

        Parameters
        ----------
        rho : ndarray of float, grid shape
            Density, values in [0, 1].
        cell_mm3 : float, optional
            The volume dV each voxel stands for, mm^3; default dx^3. (The objective passes its rescaled
            voxel volume times the mirror multiplicity, as for J_binary.)

        Returns
        -------
        value : float
            J_chan, mm^3 (in the units of ``cell_mm3``).
        grad : ndarray of float, grid shape
            Its gradient with respect to rho.
        """
        rho = self._check(rho)
        cell = self.dx_mm ** 3 if cell_mm3 is None else float(cell_mm3)
        if self.segment == 1:
            return 0.0, np.zeros(self.shape)
        b, span = self.sharpness, self.segment - 1
        e1 = np.exp(b * self._padded(rho))
        value, g_rho, g_e1 = 0.0, np.zeros(self.shape), np.zeros_like(e1)
        for axis in range(rho.ndim):
            closed, m1, e2, m2 = self._closing(e1, axis)
            over = np.maximum(closed - rho, 0.0)
            value += float(np.sum(over ** 2) * cell)
            g_closed = 2.0 * cell * over
            g_rho -= g_closed
            # C = 1 - log(m2) / b; m2 = W' e2; e2 = e^b / m1; m1 = W e1 (W' and W: means over L voxels)
            g_m2 = np.zeros_like(m2)
            g_m2[self._crop] = -g_closed / (b * m2[self._crop])
            g_e2 = _shifted_sum(g_m2, axis, -span, 0) / self.segment
            g_m1 = -g_e2 * e2 / m1
            g_e1 += _shifted_sum(g_m1, axis, 0, span) / self.segment
        return value, g_rho + self._fold(b * e1 * g_e1)


def narrow_voids(rho: np.ndarray, dx_mm: float, width_mm: float, mirror: tuple[bool, ...] | None = None,
                 sharpness: float = SHARPNESS) -> tuple[float, np.ndarray]:
    """J_chan of a density (module docstring) in mm^3, and its gradient: `NarrowVoids` for one call.

    Parameters
    ----------
    rho : (H, W) or (D, H, W) ndarray of float
        Density of the grid (a half/quadrant/octant with `mirror`), values in [0, 1].
    dx_mm : float
        Voxel edge, mm.
    width_mm : float
        Minimum open channel width w, mm.
    mirror : tuple of bool, optional
        Per axis, a mirror plane at the index-0 face.
    sharpness : float
        b of the soft maximum (`SHARPNESS`).

    Returns
    -------
    value : float
        J_chan with dV = dx^3, mm^3.
    grad : ndarray of float, grid shape
        dJ_chan/drho, mm^3.

    Examples
    --------
    Against a 1 mm width on 0.1 mm voxels, a slot 0.4 mm wide through a block costs nearly its
    volume (0.4 x 2 x 2 mm = 1.6 mm^3); one 1.2 mm wide next to nothing:

    >>> narrow = np.ones((30, 20, 20)); narrow[13:17] = 0.0
    >>> wide = np.ones((30, 20, 20)); wide[9:21] = 0.0
    >>> print(f"{narrow_voids(narrow, 0.1, 1.0)[0]:.2f} {narrow_voids(wide, 0.1, 1.0)[0]:.4f}")
    1.55 0.0122
    """
    rho = np.asarray(rho, dtype=float)
    return NarrowVoids(rho.shape, dx_mm, width_mm, mirror, sharpness)(rho)
