"""Evidence for docs/materials.md: the two-material forward model against analytic releases and finite differences.

Prints the tables quoted in docs/evidence/materials.md and writes docs/figures/materials_shell.png (a drug
sphere in a barrier shell against its delayed analytic release) and docs/figures/materials_targets.png (the
three release shapes a barrier opens). Usage: python -m benchmarks.materials_evidence [--quick]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.ndimage import gaussian_filter  # noqa: E402

from design.forward.release import ramp_release  # noqa: E402
from design.forward.simulator import N_MIN, simulate  # noqa: E402
from design.forward.twomaterial import simulate_two, two_material_gradient  # noqa: E402

FIGURES = Path(__file__).resolve().parents[1] / "docs" / "figures"
RADIUS, SHELL, HALF_WIDTH = 0.5, 0.3, 0.9


def _shell_case(n: int):
    dx = 2 * HALF_WIDTH / n
    c = (np.arange(n) + 0.5) * dx - HALF_WIDTH
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    return dx, (r < RADIUS).astype(float), ((r >= RADIUS) & (r < RADIUS + SHELL)).astype(float)


def _delayed_sphere(tau, delay):
    depth = np.clip(tau - delay, 0, None)
    return 4 / 3 * np.pi * (RADIUS ** 3 - np.clip(RADIUS - depth, 0, None) ** 3)


def shell_table(sizes: list[int], speeds: list[float]) -> None:
    """Time error of the delayed sphere, first release against shell / s, per barrier speed and grid size."""
    print("\n## drug sphere (R = 0.5 mm) in a barrier shell (0.3 mm), domain 1.8 mm across")
    print("| s | voxels across | dx (mm) | max time error (mm) | in dx | first release - shell/s (mm) | "
          "max |C - C*| / V | seconds |")
    print("|---|---|---|---|---|---|---|---|")
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    for s in speeds:
        for n in sizes:
            dx, drug, barrier = _shell_case(n)
            start = time.perf_counter()
            rel = simulate_two(drug, barrier, dx, s, total_time_mm=SHELL / s + RADIUS + 0.1)
            seconds = time.perf_counter() - start
            f = np.linspace(0.02, 0.98, 49)
            t_sim = np.interp(f * rel.released_mm3[-1], rel.released_mm3, rel.tau_mm)
            t_err = float(np.abs(t_sim - (SHELL / s + RADIUS * (1 - (1 - f) ** (1 / 3)))).max())
            first = float(rel.tau_mm[np.argmax(rel.released_mm3 > 0)])
            exact = _delayed_sphere(rel.tau_mm, SHELL / s)
            c_err = float(np.abs(rel.released_mm3 - exact).max() / (4 / 3 * np.pi * RADIUS ** 3))
            print(f"| {s:g} | {n} | {dx:.4f} | {t_err:.4f} | {t_err / dx:.2f} | {first - SHELL / s:+.4f} | "
                  f"{c_err:.3f} | {seconds:.2f} |")
            if n == sizes[-1]:
                line, = ax.plot(rel.tau_mm, rel.released_mm3, label=f"s = {s:g}, {n} voxels")
                ax.plot(rel.tau_mm, exact, "--", color=line.get_color(), lw=1)
    ax.set_xlabel("tau (mm of drug dissolved)")
    ax.set_ylabel("drug released (mm$^3$)")
    ax.set_title("drug sphere in a barrier shell: simulated (solid) and delayed analytic (dashed)", fontsize=9)
    ax.legend(fontsize=8)
    fig.savefig(FIGURES / "materials_shell.png", dpi=120)
    plt.close(fig)


def _box(shape_xy, length, faces_open, coat):
    nx, ny = shape_xy
    pad = {f: 0 if f in faces_open else coat for f in ("-x", "+x", "-y", "+y", "-z", "+z")}
    shape = (nx + pad["-x"] + pad["+x"], ny + pad["-y"] + pad["+y"], length + pad["-z"] + pad["+z"])
    drug = np.zeros(shape)
    drug[pad["-x"]:pad["-x"] + nx, pad["-y"]:pad["-y"] + ny, pad["-z"]:pad["-z"] + length] = 1.0
    return drug, 1.0 - drug


def slab_table(scales: list[int]) -> None:
    """Coated boxes: insoluble coats with one or two open faces, and a soluble coat on the z faces (with anisotropy)."""
    print("\n## coated boxes (drug 0.6 x 0.7 x 1.0 mm at dx = 0.1 mm; insoluble coat 2 voxels)")
    print("| open faces | analytic | max |C - C*| (mm^3) |")
    print("|---|---|---|")
    for faces, rate in ((("+z",), 1), (("-z", "+z"), 2)):
        drug, barrier = _box((6, 7), 10, faces, 2)
        rel = simulate_two(drug, barrier, 0.1, 0.0)
        exact = 0.42 * np.minimum(rate * rel.tau_mm, 1.0)
        print(f"| {' '.join(faces)} | 0.42 min({rate} tau, 1) | {np.abs(rel.released_mm3 - exact).max():.2e} |")
    print("\n## drug box 2.4 x 2.4 x 0.8 mm, z faces coated 0.1 mm at s = 0.5, sides open")
    print("| anisotropy | dx (mm) | max |C - C*| / V | at tau (mm) |")
    print("|---|---|---|---|")
    for a in (1.0, 0.5):
        for k in scales:
            drug, barrier = _box((24 * k, 24 * k), 8 * k, ("-x", "+x", "-y", "+y"), k)
            rel = simulate_two(drug, barrier, 0.1 / k, 0.5, anisotropy=a)
            t = rel.tau_mm
            side = np.clip(2.4 - 2 * t, 0, None)
            exact = 4.608 - side * side * np.clip(0.8 - 2 * a * np.clip(t - 0.1 / (0.5 * a), 0, None), 0, None)
            err = np.abs(rel.released_mm3 - exact)
            print(f"| {a:g} | {0.1 / k:.4f} | {err.max() / rel.drug_volume_mm3:.4f} | {t[np.argmax(err)]:.3f} |")


def sealed_and_equivalence() -> None:
    """s = 0 with a closed shell, then with a hole; s = 1 against the one-material model."""
    dx, drug, barrier = _shell_case(24)
    rel = simulate_two(drug, barrier, dx, 0.0)
    print("\n## insoluble shell (s = 0), 24 voxels across")
    print(f"closed: max released {rel.released_mm3.max():.1e} mm^3, sealed {rel.sealed_mm3:.4f} of "
          f"{rel.drug_volume_mm3:.4f} mm^3, lowest drug u {rel.u_mm[drug > 0].min():.3g} mm "
          f"(open paths end by {rel.open_time_mm:.3g} mm)")
    c = (np.arange(24) + 0.5) * dx - HALF_WIDTH
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    opened = simulate_two(drug, np.where((x * x + y * y < 0.01) & (z > 0), 0.0, barrier), dx, 0.0)
    print(f"with a 0.2 mm hole: sealed {opened.sealed_mm3:.4f} mm^3, released {opened.released_mm3[-1]:.4f} of "
          f"{opened.drug_volume_mm3:.4f} mm^3 by tau = {opened.total_time_mm:.3f} mm")
    rng = np.random.default_rng(3)
    d = gaussian_filter(rng.random((9, 10, 11)), 1.0)
    b = 0.9 * (1.0 - d) * gaussian_filter(rng.random(d.shape), 1.0)
    two = simulate_two(d, b, 0.2, 1.0, total_time_mm=1.0)
    one = simulate(d + b, 0.2, total_time_mm=1.0)
    n = (d + b) + (1 - d - b) * N_MIN
    ref = ramp_release(one.u_mm.ravel(), (n * 0.2).ravel(), (d * 0.2 ** 3).ravel(), one.dtau_mm, 1001)
    print("\n## s = 1 against the one-material model of rho_d + rho_b (drug weights)")
    print(f"max |u - u_one| = {np.abs(two.u_mm - one.u_mm).max():.1e} mm, "
          f"max |C - C_one(drug weights)| = {np.abs(two.released_mm3 - ref).max():.1e} mm^3")


def _mixture(shape, seed):
    rng = np.random.default_rng(seed)
    g = np.stack([gaussian_filter(rng.standard_normal(shape), 1.5) for _ in range(3)])
    e = np.exp(3.0 * (g - g.mean()) / g.std())
    p = e / e.sum(axis=0)
    return p[0], p[1]


def gradient_table() -> None:
    """Directional derivatives against central differences (step 1e-6), as in tests/test_twomaterial.py."""
    print("\n## gradient against central differences (step 1e-6)")
    print("| grid | mirror | anisotropy | s | drug: err / sum|g d| | barrier: err / sum|g d| | dJ/ds: rel. err |")
    print("|---|---|---|---|---|---|---|")
    for shape, mirror, aniso, s in (((20, 24), None, 1.0, 0.4), ((10, 12, 9), None, 1.0, 0.4),
                                    ((10, 12, 9), (True, False, True), 1.0, 2.0), ((10, 12, 9), None, 0.6, 0.3)):
        drug, barrier = _mixture(shape, 1)
        rng = np.random.default_rng(2)
        base = simulate_two(drug, barrier, 0.3, s, mirror=mirror, anisotropy=aniso)
        target, w_u = 0.9 * base.released_mm3, 1e-3 * rng.standard_normal(shape)

        def J(d, b, speed=s):
            r = simulate_two(d, b, 0.3, speed, mirror=mirror, anisotropy=aniso, total_time_mm=base.total_time_mm)
            return 0.5 * r.dtau_mm * np.sum((r.released_mm3 - target) ** 2) / r.total_time_mm + np.sum(w_u * r.u_mm)

        grad = two_material_gradient(base, (base.released_mm3 - target) * base.dtau_mm / base.total_time_mm, w_u)
        row, eps, void = [], 1e-6, 1.0 - drug - barrier
        for g, dd, db, rho in ((grad.drug, 1, 0, drug), (grad.barrier, 0, 1, barrier)):
            direction = gaussian_filter(rng.standard_normal(shape), 1.0) * rho * void
            fd = (J(drug + dd * eps * direction, barrier + db * eps * direction)
                  - J(drug - dd * eps * direction, barrier - db * eps * direction)) / (2 * eps)
            row.append(abs(np.sum(g * direction) - fd) / np.sum(np.abs(g * direction)))
        fd = (J(drug, barrier, s + eps) - J(drug, barrier, s - eps)) / (2 * eps)
        row.append(abs(grad.speed - fd) / abs(fd))
        print(f"| {shape} | {mirror} | {aniso:g} | {s:g} | {row[0]:.1e} | {row[1]:.1e} | {row[2]:.1e} |")


def targets_figure() -> None:
    """Three composites a single material cannot match: an open cup, a cup with a soluble lid, two pulses.

    One barrier speed serves lid and walls, so the walls and floor are made thick enough not to be crossed
    within the curve (`_walled`): only the +z face lets water in."""
    dx, s = 0.1, 0.25
    cases = {}
    cup = np.zeros((10, 10, 14))
    cup[1:-1, 1:-1, 1:] = 1.0                       # drug 0.8 x 0.8 x 1.3 mm, open at +z
    cases["open cup: constant rate"] = (cup, 1.0 - cup, 0.0)
    lid = np.zeros((10, 10, 16))
    lid[1:-1, 1:-1, 1:14] = 1.0
    barrier = 1.0 - lid
    barrier[1:-1, 1:-1, 14:] = 1.0                  # a 0.2 mm lid
    cases["cup with a soluble lid: delay, then constant"] = (lid, barrier, s)
    pulses = np.zeros((10, 10, 16))
    pulses[1:-1, 1:-1, 1:6] = 1.0
    pulses[1:-1, 1:-1, 9:16] = 1.0
    cases["two drug layers, a barrier between: two pulses"] = (pulses, 1.0 - pulses, s)
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6.5, 6), constrained_layout=True)
    print("\n## release shapes a barrier opens (dx = 0.1 mm, barrier speed as given)")
    for name, (d, b, speed) in cases.items():
        rel = _walled(d, b, dx, speed)
        top.plot(rel.tau_mm, rel.released_mm3, label=name)
        bottom.plot(rel.tau_mm, np.gradient(rel.released_mm3, rel.tau_mm))
        print(f"{name}: drug {rel.drug_volume_mm3:.3f} mm^3, released {rel.released_mm3[-1]:.3f} mm^3 by tau "
              f"{rel.total_time_mm:.2f} mm")
    top.set_ylabel("drug released (mm$^3$)")
    top.legend(fontsize=8)
    bottom.set_ylabel("rate (mm$^3$/mm)")
    bottom.set_xlabel("tau (mm of drug dissolved)")
    fig.savefig(FIGURES / "materials_targets.png", dpi=120)
    plt.close(fig)


def _walled(drug, barrier, dx, speed):
    """Pad the composite's walls and floor with barrier thick enough (at `speed`) not to be crossed by tau = 2.5."""
    thick = int(np.ceil(2.5 * speed / dx)) + 1  # 1 voxel at s = 0
    pad = ((thick, thick), (thick, thick), (thick, 0))
    return simulate_two(np.pad(drug, pad), np.pad(barrier, pad, constant_values=1.0), dx, speed, total_time_mm=2.5)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="smaller grids")
    args = parser.parse_args()
    FIGURES.mkdir(parents=True, exist_ok=True)
    shell_table([24, 48] if args.quick else [36, 72, 144], [1.0, 0.5, 0.25])
    slab_table([1, 2] if args.quick else [1, 2, 4])
    sealed_and_equivalence()
    gradient_table()
    targets_figure()


if __name__ == "__main__":
    main()
