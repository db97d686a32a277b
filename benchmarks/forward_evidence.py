"""Evidence for docs/forward.md: convergence against analytic curves, eq. (5) residuals, FD gradient checks.

Writes docs/figures/forward_convergence.png, forward_nested.png, forward_fd_check.png and prints the
tables quoted in docs/forward.md. Usage: python -m benchmarks.forward_evidence [--quick]
The last line is the headline: sphere_error_at_96: <relative max error>.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.ndimage import gaussian_filter  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
from benchmarks.analytic import SHAPES, centres, release_error  # noqa: E402
from design import release_gradient, simulate  # noqa: E402
from design.forward.fmm import eikonal_residual, march  # noqa: E402
from design.forward.simulator import slowness  # noqa: E402

FIGURES = ROOT / "docs" / "figures"


def convergence(sizes: list[int]) -> dict[str, list[float]]:
    errors = {name: [release_error(name, n) for n in sizes] for name in SHAPES}
    fig, ax = plt.subplots(figsize=(5.5, 4), constrained_layout=True)
    for name, err in errors.items():
        ax.loglog(sizes, err, "o-", label=name)
    ref = np.array(sizes, dtype=float)
    ax.loglog(ref, errors["sphere"][0] * ref[0] / ref, "k--", lw=0.8, label="slope -1")
    ax.set_xlabel("voxels across the bounding box")
    ax.set_ylabel("max |C - C*| / volume")
    ax.set_title("release curve error vs analytic (Fig. 3d)")
    ax.legend()
    fig.savefig(FIGURES / "forward_convergence.png", dpi=120)
    plt.close(fig)
    print("| voxels across | " + " | ".join(SHAPES) + " |")
    print("|---|" + "---|" * len(SHAPES))
    for k, n in enumerate(sizes):
        print(f"| {n} | " + " | ".join(f"{100 * errors[s][k]:.2f} %" for s in SHAPES) + " |")
    return errors


def nested_curve(n: int) -> None:
    inside, exact, half_width, t_end = SHAPES["nested"]
    dx, (x, y, z) = centres(n, half_width)
    rel = simulate(inside(x, y, z).astype(float), dx, total_time_mm=t_end)
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.8), constrained_layout=True)
    left.plot(rel.tau_mm, exact(rel.tau_mm), "k--", label="analytic")
    left.plot(rel.tau_mm, rel.released_mm3, label=f"simulated, {n}$^3$ voxels")
    left.set_xlabel("tau (mm dissolved)")
    left.set_ylabel("released volume (mm$^3$)")
    left.set_title("ball r<0.4 in shell 0.6<r<1, void between")
    left.legend()
    im = right.imshow(rel.u_mm[:, :, n // 2], extent=(-1, 1, -1, 1), origin="lower")
    right.set_title("dissolution time u, mid-slice (Fig. 2)")
    right.set_xlabel("y (mm)")
    right.set_ylabel("x (mm)")
    fig.colorbar(im, ax=right, label="u (mm)")
    fig.savefig(FIGURES / "forward_nested.png", dpi=120)
    plt.close(fig)


def residuals() -> None:
    rng = np.random.default_rng(0)
    print("| grid | mirror | max abs eq. (5) residual (mm) | T (mm) |")
    print("|---|---|---|---|")
    for shape, mirror in (((96, 96), (False, False)), ((64, 64, 64), (False, False, False)),
                          ((64, 64, 64), (True, False, True))):
        g = gaussian_filter(rng.standard_normal(shape), 2.0)
        rho = 1.0 / (1.0 + np.exp(-8.0 * (g - g.mean()) / g.std()))
        m = march(slowness(rho), 1.0 / 64, mirror)
        res = np.abs(eikonal_residual(m)).max()
        print(f"| {'x'.join(map(str, shape))} | {''.join('xyz'[a] for a, f in enumerate(mirror) if f) or '-'} "
              f"| {res:.2e} | {m.interior(m.u_pad).max():.3f} |")


def fd_check() -> float:
    rng = np.random.default_rng(1)
    fig, ax = plt.subplots(figsize=(5.5, 4), constrained_layout=True)
    worst = 0.0
    for shape in ((40, 48), (16, 18, 14)):
        g = gaussian_filter(rng.standard_normal(shape), 1.5)
        rho = 0.001 + 0.998 / (1.0 + np.exp(-3.0 * ((g - g.mean()) / g.std() + 0.5)))
        base = simulate(rho, 0.3)
        target = 0.9 * base.released_mm3
        w_u = rng.standard_normal(shape)

        def objective(r):
            resid = r.released_mm3 - target
            return 0.5 * r.dtau_mm * np.sum(resid ** 2) / r.total_time_mm + np.sum(w_u * r.u_mm), resid

        _, resid = objective(base)
        grad = release_gradient(base, resid * base.dtau_mm / base.total_time_mm, w_u)
        d = gaussian_filter(rng.standard_normal(shape), 1.0)
        d /= np.abs(d).max()  # steps up to 10^-3.5 keep rho = 0.001 + ... inside [0, 1]
        exact = float(np.sum(grad * d))
        eps_list = np.logspace(-3.5, -9, 12)
        rel = []
        for eps in eps_list:
            jp = objective(simulate(rho + eps * d, 0.3, total_time_mm=base.total_time_mm))[0]
            jm = objective(simulate(rho - eps * d, 0.3, total_time_mm=base.total_time_mm))[0]
            rel.append(abs((jp - jm) / (2 * eps) - exact) / abs(exact))
        ax.loglog(eps_list, rel, "o-", label=f"{len(shape)}D {shape}")
        at = rel[int(np.argmin(np.abs(eps_list - 1e-6)))]
        worst = max(worst, at)
        print(f"FD check {len(shape)}D {shape}: relative error {at:.2e} at eps = 1e-6, best {min(rel):.2e}")
    ax.axhline(1e-5, color="k", lw=0.8, ls="--", label="1e-5 requirement")
    ax.set_xlabel("central-difference step eps")
    ax.set_ylabel("|FD - adjoint| / |adjoint|")
    ax.set_title("exact gradient vs central differences")
    ax.legend()
    fig.savefig(FIGURES / "forward_fd_check.png", dpi=120)
    plt.close(fig)
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="resolutions up to 48 only")
    args = parser.parse_args()
    FIGURES.mkdir(parents=True, exist_ok=True)
    sizes = [16, 24, 32, 48] if args.quick else [16, 24, 32, 48, 64, 96]
    errors = convergence(sizes)
    nested_curve(48)
    residuals()
    fd_check()
    print(f"sphere_error_at_{sizes[-1]}: {errors['sphere'][-1]:.4f}")


if __name__ == "__main__":
    main()
