"""Forward simulator speed: our fast marching (+ exact gradient) against scikit-fmm, same grid, same run.

Field: a Gaussian-blurred random field through a sigmoid, so about a fifth of the voxels are void
(rho < 1e-3) and the rest range up to solid. For each size N^3 it times, best of R repeats:
  skfmm    skfmm.travel_time(order=1) on the padded grid (phi = 0 on the padding, speed 1/n)
  forward  design.simulate (fast marching + release curve)
  fwd+grad design.simulate + design.release_gradient of a least-squares fit to a target curve
and measures the peak resident memory of a separate process that runs forward + gradient at 128^3.

Usage: python -m benchmarks.bench_forward [--quick]
The last line is the headline: fwd_grad_over_skfmm_128: <ratio>.
"""
from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

ROOT = Path(__file__).resolve().parents[1]
"""The checkout, where ``python -m benchmarks.NAME`` runs the peak-memory child."""


def void_field(n: int, seed: int = 0) -> np.ndarray:
    """(n, n, n) density in [0, 1]: blurred normal noise, standardised, through a sigmoid of slope 8."""
    g = gaussian_filter(np.random.default_rng(seed).standard_normal((n, n, n)), n / 32)
    g = (g - g.mean()) / g.std()
    return 1.0 / (1.0 + np.exp(-8.0 * g))


def _time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def _fwd_grad(rho, dx, target):
    from design import release_gradient, simulate

    release = simulate(rho, dx)
    residual = release.released_mm3 - target
    return release_gradient(release, residual * release.dtau_mm / release.total_time_mm)


def _peak_memory_child(n: int) -> None:
    rho = void_field(n)
    _fwd_grad(rho, 1.0 / n, np.zeros(1001))
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)  # kB -> MB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one repeat per size instead of three")
    parser.add_argument("--peak-memory-child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.peak_memory_child:
        _peak_memory_child(args.peak_memory_child)
        return

    import skfmm

    from design import simulate
    from design.forward.simulator import slowness

    repeats = 1 if args.quick else 3
    _fwd_grad(void_field(8), 0.1, np.zeros(1001))  # load the compiled kernels outside the timings
    ratio = {}
    print(f"{'N':>5} {'void %':>7} {'skfmm s':>8} {'forward s':>9} {'fwd+grad s':>10} {'fwd/skfmm':>9} {'fwd+grad/skfmm':>14}")
    for n in (64, 128):
        rho = void_field(n)
        dx = 1.0 / n
        target = 0.9 * simulate(rho, dx).released_mm3
        phi = np.pad(np.ones(rho.shape), 1)
        speed = np.pad(1.0 / slowness(rho), 1, constant_values=1.0)
        t_sk = _time(lambda: skfmm.travel_time(phi, speed, dx=dx, order=1), repeats)
        t_fwd = _time(lambda: simulate(rho, dx), repeats)
        t_grad = _time(lambda: _fwd_grad(rho, dx, target), repeats)
        ratio[n] = t_grad / t_sk
        print(f"{n:>5} {100 * np.mean(rho < 1e-3):>7.1f} {t_sk:>8.3f} {t_fwd:>9.3f} {t_grad:>10.3f} "
              f"{t_fwd / t_sk:>9.2f} {ratio[n]:>14.2f}")
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_forward", "--peak-memory-child", "128"], capture_output=True,
                         text=True, check=True, cwd=ROOT)
    print(f"peak resident memory, forward + gradient at 128^3 (separate process): {float(out.stdout):.0f} MB")
    print(f"fwd_grad_over_skfmm_128: {ratio[128]:.2f}")


if __name__ == "__main__":
    main()
