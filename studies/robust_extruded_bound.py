"""How well can any extruded design fit a source's release? A bound from the cross-section's offset areas.

    python -m studies.robust_extruded_bound --target sphere --resolution 128

A design of the extruded space is a prism: a cross-section Omega extruded over the height h, dissolving
from its sides and from its two end faces at unit speed (eq. 5 with rho binary). A point (p, z) of the
prism is reached at min(d(p), z, h - z), d the in-plane distance to the outside of Omega, so the prism
still holds A(t) (h - 2 t) at time t, A(t) the area of {d > t}, and releases

    C(t) = A(0) h - A(t) (h - 2 t)        (t < h / 2; all of A(0) h after).

By the coarea formula -A'(t) is the length of the level line {d = t}, and by the isoperimetric
inequality that length is at least 2 sqrt(pi A(t)); with s = sqrt(A / pi) (the radius of the disc of
equal area) every cross-section obeys s'(t) <= -1, with equality for a disc. Minimising the relative
RMSE of C against the target over all s(t) with s' <= -1 (s(0) and the extra shrink rate free, 100
pieces) therefore bounds every extruded design of height h from below (in the continuum model). The
script prints that bound, the best disc (s' = -1), and the best pixel disc on the design grid
simulated by `design.forward.simulator.simulate` (the binary solids of the design runs are pixel shapes).
For the sphere it also compares with the exact release of a continuum sphere, 4/3 pi (R^3 - (R - t)^3).
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import minimize

from design.files.targets_io import load_problem
from design.forward.simulator import simulate
from design.geometry.shapes import sample_shape
from design.inverse.config import DesignConfig
from design.inverse.objective import rel_rmse
from design.inverse.spaces import BUILD_AXIS

PIECES = 100
"""Piecewise-constant extra shrink rates over [0, h/2] in the relaxation."""


def prism_release(s0: float, extra: np.ndarray, tau: np.ndarray, h: float) -> np.ndarray:
    """C(t) of the module doc for s(t) = s0 - t - int_0^t extra (extra piecewise constant on [0, h/2])."""
    edges = np.linspace(0.0, 0.5 * h, extra.size + 1)
    shrink = np.interp(tau, edges, np.concatenate([[0.0], np.cumsum(extra) * (edges[1] - edges[0])]))
    s = np.clip(s0 - tau - shrink, 0.0, None)
    return np.pi * s0 ** 2 * h - np.pi * s ** 2 * np.clip(h - 2.0 * tau, 0.0, None)


def best_disc(tau: np.ndarray, target: np.ndarray, h: float) -> tuple[float, float]:
    """(rel. RMSE, radius) of the best disc prism, scanning the radius finely."""
    a_eq = np.sqrt(target[-1] / (np.pi * h))
    radii = np.linspace(0.7 * a_eq, 1.5 * a_eq, 4001)
    errors = [rel_rmse(prism_release(a, np.zeros(1), tau, h), target) for a in radii]
    i = int(np.argmin(errors))
    return float(errors[i]), float(radii[i])


def relaxation_bound(tau: np.ndarray, target: np.ndarray, h: float) -> tuple[float, float, np.ndarray]:
    """(rel. RMSE, s(0), extra shrink rates) minimising over every s with s' <= -1 (module doc)."""
    err0, a0 = best_disc(tau, target, h)

    def objective(p: np.ndarray) -> float:
        return rel_rmse(prism_release(p[0], p[1:], tau, h), target)

    best = None
    for rate in (0.0, 0.1, 1.0):  # a few starts: the disc, mild and strong extra shrink
        x0 = np.concatenate([[a0], np.full(PIECES, rate)])
        res = minimize(objective, x0, method="L-BFGS-B", bounds=[(1e-9, None)] + [(0.0, None)] * PIECES,
                       options={"maxiter": 3000, "maxfun": 10 ** 6})
        if best is None or res.fun < best.fun:
            best = res
    return float(min(best.fun, err0)), float(best.x[0]), best.x[1:]


def best_pixel_disc(problem, tau: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(rel. RMSE, radius) of the best disc of whole pixels of the design grid, simulated on it."""
    space, dx = problem.space, problem.dx_mm
    shape2d = space.var_shape
    centres = np.meshgrid(*[(np.arange(n) + 0.5) * dx for n in shape2d], indexing="ij")
    r = np.hypot(*centres)
    a_eq = np.sqrt(target[-1] / (np.pi * space.grid_shape[BUILD_AXIS] * dx))
    best = (np.inf, 0.0)
    for a in np.unique(r[(r > 0.85 * a_eq) & (r < 1.25 * a_eq)]):
        rho = space.to_grid((r <= a).astype(float))
        curve = simulate(rho, dx, mirror=space.mirror, total_time_mm=tau[-1], dtau_mm=tau[1] - tau[0]).released_mm3
        best = min(best, (rel_rmse(curve, target), float(a)))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", default="sphere", help="source shape or mesh (default sphere)")
    parser.add_argument("--resolution", type=int, default=128)
    args = parser.parse_args()
    problem = load_problem(DesignConfig(target=args.target, space="extruded", resolution=args.resolution))
    tau, target = problem.target.tau_mm, problem.target.released_mm3
    h = problem.space.grid_shape[BUILD_AXIS] * problem.dx_mm
    print(f"{args.target}, extruded, resolution {args.resolution}: h = {h:.4g} mm, T = {tau[-1]:.4g} mm, "
          f"target {target[-1]:.1f} mm^3")
    curves = [("the source's physical release (the design's target)", target)]
    if args.target == "sphere":
        lo, hi = sample_shape(args.target).bounds
        radius = 0.5 * float(hi[0] - lo[0])
        curves.append((f"a continuum sphere, R = {radius:.4g} mm",
                       4.0 / 3.0 * np.pi * (radius ** 3 - np.clip(radius - tau, 0.0, None) ** 3)))
    for name, curve in curves:
        bound, s0, extra = relaxation_bound(tau, curve, h)
        disc, a = best_disc(tau, curve, h)
        print(f"against {name}: relaxation bound {100 * bound:.3f}% (s(0) = {s0:.4g} mm, extra shrink "
              f"{float(np.sum(extra)) * 0.5 * h / PIECES:.3g} mm in all); best disc {100 * disc:.3f}% "
              f"(radius {a:.4g} mm)")
    err, a = best_pixel_disc(problem, tau, target)
    print(f"best pixel disc on the design grid, simulated: {100 * err:.3f}% (radius {a:.4g} mm)")


if __name__ == "__main__":
    main()
