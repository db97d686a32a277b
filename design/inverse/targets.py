"""Target release curves C*(tau) for inverse design, and their feasibility (sections 3.3, 5.2).

Every target lives on the design's tau grid ``tau_k = k T / (K - 1)`` (``dtau = T / 1000``,
section 3.4), in simulation units: tau in mm dissolved, released amount in mm^3 of solid.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from design.errors import DesignError
from design.forward.simulator import simulate
from design.geometry.voxelize import voxelize

TAU_SAMPLES = 1001
"""Points of a design's tau grid by default: ``dtau = T / 1000`` (section 3.4)."""
SPHERE_AREA_COEF = (36.0 * np.pi) ** (1.0 / 3.0)
"""Surface area of a sphere of volume V is ``SPHERE_AREA_COEF * V**(2/3)``."""
ISO_TOLERANCE = 0.15
"""Relative slack of the feasibility check on the isoperimetric bound (`check_feasibility`)."""
TAIL_FRACTION = 0.02
"""The feasibility check ignores the bound once less than this fraction of the total is left to dissolve."""


@dataclass(frozen=True)
class Target:
    """A target cumulative release curve.

    Attributes
    ----------
    tau_mm : (K,) ndarray of float, mm
        Uniform grid from 0 to T.
    released_mm3 : (K,) ndarray of float, mm^3
    source : str
        Where it came from (mesh path, CSV path or analytic description).
    """

    tau_mm: np.ndarray
    released_mm3: np.ndarray
    source: str

    def __post_init__(self) -> None:
        if self.tau_mm.shape != self.released_mm3.shape or self.tau_mm.ndim != 1 or self.tau_mm.size < 3:
            raise DesignError(f"target needs matching 1D tau and release arrays with >= 3 samples, got "
                              f"{self.tau_mm.shape} and {self.released_mm3.shape}")

    @property
    def total_time_mm(self) -> float:
        return float(self.tau_mm[-1])

    @property
    def final_mm3(self) -> float:
        return float(self.released_mm3[-1])


def tau_grid(total_time_mm: float, samples: int = TAU_SAMPLES) -> np.ndarray:
    """The design's tau grid, ``dtau = T / (samples - 1)`` (`TAU_SAMPLES` by default)."""
    if not total_time_mm > 0 or samples < 3:
        raise DesignError(f"need T > 0 mm and >= 3 samples, got T = {total_time_mm}, samples = {samples}")
    return np.linspace(0.0, total_time_mm, samples)


def resample_monotone(tau_mm: np.ndarray, released_mm3: np.ndarray, grid_mm: np.ndarray) -> np.ndarray:
    """Resample a cumulative curve onto ``grid_mm`` with a monotone (PCHIP) interpolant.

    A curve that starts after tau = 0 is taken to start from (0, 0); past its last sample it
    is held constant (the release is over).

    Raises
    ------
    DesignError
        If tau is not strictly increasing or the release decreases.
    """
    tau = np.asarray(tau_mm, dtype=float)
    c = np.asarray(released_mm3, dtype=float)
    if tau.ndim != 1 or tau.shape != c.shape or tau.size < 2:
        raise DesignError(f"need two matching 1D columns with >= 2 rows, got {tau.shape} and {c.shape}")
    if np.any(np.diff(tau) <= 0) or tau[0] < 0:
        raise DesignError("tau_mm must be >= 0 and strictly increasing")
    if np.any(np.diff(c) < 0):
        k = int(np.argmax(np.diff(c) < 0))
        raise DesignError(f"cumulative release decreases at tau = {tau[k + 1]:.4g} mm "
                          f"({c[k]:.4g} -> {c[k + 1]:.4g} mm^3); a target must be non-decreasing")
    if tau[0] > 0:
        tau, c = np.concatenate([[0.0], tau]), np.concatenate([[0.0], c])
    out = PchipInterpolator(tau, c, extrapolate=False)(np.clip(grid_mm, 0.0, tau[-1]))
    return np.asarray(out, dtype=float)


def curve_end_mm(tau_mm: np.ndarray, released_mm3: np.ndarray) -> float:
    """When a cumulative curve reaches its final value (its last rise), mm."""
    c = np.asarray(released_mm3, dtype=float)
    rising = np.flatnonzero(c < c[-1] - 1e-9 * max(abs(c[-1]), 1e-300))
    return float(tau_mm[min(rising[-1] + 1, c.size - 1)]) if rising.size else float(tau_mm[0])


def target_from_curve(tau_mm: np.ndarray, released_mm3: np.ndarray, total_time_mm: float, samples: int = TAU_SAMPLES, *,
                      source: str) -> Target:
    """A measured or tabulated ``tau_mm,released_mm3`` curve resampled onto the design grid.

    Parameters
    ----------
    tau_mm, released_mm3 : (N,) ndarrays of float
        The curve as written (`design.files.targets_io.read_curve_csv`).
    total_time_mm : float
        The design's horizon T, mm.
    samples : int
    source : str
        Where the curve comes from (a CSV path): names it in errors; the target's source is ``csv:SOURCE``.

    Raises
    ------
    DesignError
        If the curve is not monotone, or if it still rises after the horizon T: no design in the domain
        releases anything after T (the all-solid domain is dissolved by then), and cutting the curve at T
        would understate its total.
    """
    tau, c = tau_mm, released_mm3
    end = curve_end_mm(tau, c)
    if end > total_time_mm:
        at_t = float(np.interp(total_time_mm, tau, c, left=0.0))
        raise DesignError(f"{source}: the curve rises until tau = {end:.4g} mm (to {c[-1]:.4g} mm^3), past the "
                          f"design domain's horizon T = {total_time_mm:.4g} mm, by which it has released "
                          f"{at_t:.4g} mm^3 ({at_t / c[-1]:.1%}); enlarge the domain so that T >= {end:.4g} mm")
    grid = tau_grid(total_time_mm, samples)
    return Target(grid, resample_monotone(tau, c, grid), f"csv:{source}")


def constant_acceleration(total_time_mm: float, final_mm3: float, duration_mm: float,
                          rate_ratio: float = 1.0, samples: int = TAU_SAMPLES) -> Target:
    """Analytic target with C'' constant until the release ends (Fig. 7).

    Parameters
    ----------
    total_time_mm : float
        Design duration T, mm.
    final_mm3 : float
        Total release, mm^3.
    duration_mm : float
        When the release ends, mm (<= T).
    rate_ratio : float
        Final over initial release rate, >= 0; 1 gives zero-order (constant-rate) release.
    """
    if not 0 < duration_mm <= total_time_mm or not final_mm3 > 0 or rate_ratio < 0:
        raise DesignError(f"need 0 < duration <= T = {total_time_mm:.4g} mm, final > 0 mm^3, rate ratio >= 0; "
                          f"got {duration_mm:.4g} mm, {final_mm3:.4g} mm^3, {rate_ratio:.4g}")
    grid = tau_grid(total_time_mm, samples)
    s = np.clip(grid / duration_mm, 0.0, 1.0)
    # C'(tau) = v0 (1 + (q - 1) s) with v0 fixed by C(duration) = final: C = final (s + (q-1) s^2/2) / ((1+q)/2)
    c = final_mm3 * (s + 0.5 * (rate_ratio - 1.0) * s * s) / (0.5 * (1.0 + rate_ratio))
    kind = "zero-order" if rate_ratio == 1.0 else f"const-accel(q={rate_ratio:g})"
    return Target(grid, c, f"analytic:{kind},final={final_mm3:.6g}mm3,duration={duration_mm:.6g}mm")


def target_from_density(rho: np.ndarray, dx_mm: float, total_time_mm: float, source: str,
                        samples: int = TAU_SAMPLES) -> Target:
    """Simulate a full (unmirrored) density grid on the design's tau grid (Fig. 6 targets)."""
    release = simulate(np.asarray(rho, dtype=float), dx_mm, total_time_mm=total_time_mm,
                       dtau_mm=total_time_mm / (samples - 1))
    return Target(np.asarray(release.tau_mm), np.asarray(release.released_mm3), source)


def target_from_mesh(mesh, dx_mm: float, total_time_mm: float, source: str, samples: int = TAU_SAMPLES, *,
                     origin_mm: np.ndarray | None = None, shape: tuple[int, int, int] | None = None) -> Target:
    """Voxelise a source mesh (mm) and simulate its release.

    ``origin_mm`` and ``shape`` give the design grid (`design.geometry.voxelize.voxelize`); pass them so that
    the target is the source as the design grid represents it, not on a grid offset from it.
    """
    return target_from_density(voxelize(mesh, dx_mm, origin_mm=origin_mm, shape=shape), dx_mm, total_time_mm,
                               source, samples)


@dataclass(frozen=True)
class Feasibility:
    """Result of `check_feasibility`.

    Attributes
    ----------
    problems : tuple of str
        Violations that make the target unreachable; empty when feasible.
    iso_intervals : tuple of (float, float, float)
        ``(tau_start_mm, tau_end_mm, worst_ratio)`` where the release rate is below the
        isoperimetric bound, worst_ratio = min rate / bound there.
    """

    problems: tuple[str, ...]
    iso_intervals: tuple[tuple[float, float, float], ...]

    @property
    def feasible(self) -> bool:
        return not self.problems

    def text(self) -> str:
        """A human-readable report."""
        if self.feasible:
            return "target is feasible: monotone, starts at 0, fits the domain, obeys the isoperimetric bound"
        return "target is infeasible:\n" + "\n".join(f"  - {p}" for p in self.problems)


def isoperimetric_bound(target: Target) -> tuple[np.ndarray, np.ndarray]:
    """Release rate per interval and its lower bound (section 5.2).

    At every instant the rate (mm^3 per mm of tau, i.e. the dissolving front's area in mm^2)
    is at least the area of a sphere holding the volume still to dissolve.

    Returns
    -------
    rate, bound : (K-1,) ndarrays of float, mm^2
    """
    c = target.released_mm3
    rate = np.diff(c) / np.diff(target.tau_mm)
    remaining = np.clip(c[-1] - 0.5 * (c[1:] + c[:-1]), 0.0, None)
    return rate, _sphere_area(remaining)


def _sphere_area(volume_mm3):
    """Area of a sphere holding ``volume_mm3``, mm^2: the least area of any front around that volume."""
    return SPHERE_AREA_COEF * np.asarray(volume_mm3, float) ** (2.0 / 3.0)


def isotonic_fit(values: np.ndarray, end_block: int = 1) -> np.ndarray:
    """The non-decreasing sequence nearest to ``values`` in least squares whose last ``end_block`` values are
    equal (pool adjacent violators, the last ``end_block`` samples pooled from the start).

    Unconstrained (``end_block`` 1), the last value is the largest mean of any tail of the data, which on a noisy
    plateau is one high sample; pooling the last few makes the final level the mean of at least that many.

    Parameters
    ----------
    values : (N,) ndarray of float
    end_block : int
        At least 1; at most N.

    Returns
    -------
    (N,) ndarray of float
        Each run of pooled samples holds their mean; where ``values`` never decreases (and its last
        ``end_block`` are equal) it is returned unchanged.
    """
    y = np.asarray(values, float)
    end_block = min(max(int(end_block), 1), y.size)
    head = y[:y.size - end_block]
    blocks = [(float(v), 1) for v in head] + ([(float(np.mean(y[head.size:])), end_block)] if y.size else [])
    means, counts = [], []
    for mean, count in blocks:
        means.append(mean)
        counts.append(count)
        while len(means) > 1 and means[-2] > means[-1]:      # pool the last two blocks
            n = counts[-2] + counts[-1]
            means[-2] = (means[-2] * counts[-2] + means[-1] * counts[-1]) / n
            counts[-2] = n
            del means[-1], counts[-1]
    return np.repeat(means, counts)


def project_isoperimetric(tau_mm: np.ndarray, released_mm3: np.ndarray, slack: float = 0.5 * ISO_TOLERANCE,
                          tail_fraction: float = TAIL_FRACTION) -> np.ndarray:
    """The curve lowered as little as needed to release at least ``(1 - slack)`` times the isoperimetric bound
    (`isoperimetric_bound`, section 5.2) on every interval until only ``tail_fraction`` of the total is left, its
    final value kept: the set `check_feasibility` accepts, with its slack and tail (which it widens by the voxel
    size) or stricter.

    A sweep from the end: on the interval from sample k to k+1 (sample k+1 already final) the bound
    ``(c[k+1] - c[k]) / dtau >= (1 - slack) A(c_end - (c[k] + c[k+1]) / 2)`` holds for every c[k] at or below one
    value (with u = c[k+1] - c[k], ``u - a (r + u / 2)^(2/3)`` is convex and <= 0 at u = 0, so it has one root),
    which bisection finds; c[k] is lowered to it where it lies above, and never below 0. The result is
    non-decreasing wherever release remains.

    Parameters
    ----------
    tau_mm, released_mm3 : (N,) ndarray of float
        A non-decreasing curve on increasing tau, mm and mm^3.
    slack : float
        In [0, 1): the bound is relaxed by this fraction (the check allows `ISO_TOLERANCE`; the default
        keeps half of that as a margin for resampling onto the design grid).
    tail_fraction : float
        Intervals with less than this fraction of the total left to dissolve (at their middle) are not
        constrained, as in the check.

    Returns
    -------
    (N,) ndarray of float, mm^3
    """
    tau = np.asarray(tau_mm, float)
    c = np.array(released_mm3, float)
    end = c[-1]
    factor = 1.0 - slack
    tail = tail_fraction * abs(end)
    for k in range(c.size - 2, -1, -1):
        a = factor * (tau[k + 1] - tau[k])
        r = max(end - c[k + 1], 0.0)
        left = r + 0.5 * (c[k + 1] - c[k])
        if left <= tail or c[k + 1] - c[k] >= a * _sphere_area(left):
            continue
        lo, hi = 0.0, max(c[k + 1], 0.0)                    # u in [lo, hi]: hi is the most c[k] can drop
        if hi - a * _sphere_area(r + 0.5 * hi) < 0.0:
            c[k] = 0.0                                       # not even from 0: flat at 0 (the check names it)
            continue
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if mid - a * _sphere_area(r + 0.5 * mid) >= 0.0:
                hi = mid
            else:
                lo = mid
        c[k] = c[k + 1] - hi
    return c


def check_feasibility(target: Target, domain_volume_mm3: float, *, dx_mm: float = 0.0,
                      domain_area_mm2: float = 0.0, iso_tolerance: float = ISO_TOLERANCE,
                      tail_fraction: float = TAIL_FRACTION) -> Feasibility:
    """Check a target before optimising: monotone, starts at 0, fits the domain, isoperimetric bound.

    Parameters
    ----------
    target : Target
    domain_volume_mm3 : float
        Volume of the full design domain, mm^3.
    dx_mm, domain_area_mm2 : float
        Voxel edge and the domain's surface area. The voxel model of eq. (6) already releases part
        of a voxel at tau = 0 where u_i < n_i dx (corner and edge voxels of the front), so a curve
        "starts at 0" if C*(0) is at most one voxel layer, dx times the domain's area; the
        isoperimetric bound is checked from tau = dx on for the same reason. 0 (default) demands
        an exact start at 0 and checks from tau = 0.
    iso_tolerance : float
        Relative slack on the isoperimetric bound; a simulated voxel release undershoots it by a
        few percent where the front is discretised (measured on voxelised spheres, see tests).
    tail_fraction : float
        Ignore the bound once less than this fraction of the total, or less than a ball of radius
        3 dx, is left to dissolve: there single voxels dominate and the bound is meaningless.
    """
    c = target.released_mm3
    problems = []
    scale = max(abs(target.final_mm3), 1e-12)
    start_tol = max(dx_mm * domain_area_mm2, 1e-6 * scale)
    if abs(c[0]) > start_tol:
        problems.append(f"release must start at 0 mm^3 (within one voxel layer, {start_tol:.4g} mm^3), "
                        f"starts at {c[0]:.4g} mm^3")
    dec = np.flatnonzero(np.diff(c) < -1e-9 * scale)
    if dec.size:
        problems.append(f"release decreases at tau = {target.tau_mm[dec[0] + 1]:.4g} mm")
    if not target.final_mm3 > 0:
        problems.append("release never becomes positive")
    if target.final_mm3 > domain_volume_mm3:
        problems.append(f"total release {target.final_mm3:.4g} mm^3 exceeds the domain volume "
                        f"{domain_volume_mm3:.4g} mm^3")
    rate, bound = isoperimetric_bound(target)
    remaining = c[-1] - 0.5 * (c[1:] + c[:-1])
    late = 0.5 * (target.tau_mm[1:] + target.tau_mm[:-1]) >= dx_mm
    # the last few voxel layers of a converging front are dominated by discretisation error
    tail = max(tail_fraction * scale, 4.0 / 3.0 * np.pi * (3.0 * dx_mm) ** 3)
    bad = (rate < (1.0 - iso_tolerance) * bound) & (remaining > tail) & late
    intervals = []
    if bad.any():
        edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            worst = float(np.min(rate[a:b] / bound[a:b]))
            intervals.append((float(target.tau_mm[a]), float(target.tau_mm[b]), worst))
            problems.append(f"release rate below the isoperimetric bound for tau in "
                            f"[{target.tau_mm[a]:.4g}, {target.tau_mm[b]:.4g}] mm (rate/bound down to "
                            f"{worst:.3f}): no shape releases this slowly with that much volume left")
    return Feasibility(tuple(problems), tuple(intervals))
