"""Benchmark of the incremental-compliance term (section 3.6) against scikit-fmm's forward solve.

Fields on an N^3 design grid: "void", the blurred random field of `bench_forward.void_field`
(sigma N/32: a network of members one or two elements thick, some floating or hinged, the hardest
case for the elasticity solver), and "design",
the same construction with sigma N/12 and 55% solid (larger, mostly connected members, closer to an
optimised design). The ICO term sees the quadrant (N/2, N/2, N), mirror planes in x and y, z the
build direction, L = 8 layers, the default coarsening (2 voxels per element edge), SIMP.
For N = 64 and 128 and each field it reports, in the same process:
  skfmm      skfmm.travel_time(order=1) on the padded N^3 grid (as bench_forward), best of R
  ico cold   one J_fab + gradient (all L layers) without previous solutions: the layers in
             sequence, each from the solution of the layer below (the first evaluation of a run)
  ico warm   one J_fab + gradient of a slightly changed design (an optimiser step: +-1% smooth
             change of rho), warm-started from the previous solutions, the layers solved
             concurrently on all cores, as in every optimisation iteration after the first
  PCG iterations per layer, cold and warm
the PCG iteration counts of the solver variants at both sizes (V-cycle; W-cycle; W-cycle with
island deflation, the default), and the peak resident memory of a separate process that runs the
128^3 evaluations. The coarsening error is measured at 64^3: J_fab normalised by the uniform start design, and the gradient's
direction, at 2 and 4 voxels per element against the uncoarsened grid; so is the PCG tolerance's:
J_fab and its gradient of a warm-started evaluation against a 1e-10 solve.

Usage: python -m benchmarks.bench_ico [--quick] [--skip-coarsening] [--skip-solvers]
The last line is the headline: ico_over_skfmm_128 = <warm ICO time / skfmm time at 128^3, void field>.
"""
from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

from benchmarks.bench_forward import void_field

ROOT = Path(__file__).resolve().parents[1]
"""The checkout, where ``python -m benchmarks.NAME`` runs the peak-memory child."""


def _quadrant(rho_full: np.ndarray) -> np.ndarray:
    n = rho_full.shape[0]
    return np.ascontiguousarray(rho_full[n // 2:, n // 2:, :])


def _step(rho: np.ndarray, seed: int = 1) -> np.ndarray:
    """A small smooth change of the design, like one optimiser step."""
    noise = gaussian_filter(np.random.default_rng(seed).standard_normal(rho.shape), 3.0)
    return np.clip(rho + 0.01 * noise / noise.std(), 0.0, 1.0)


def design_field(n: int, seed: int = 0) -> np.ndarray:
    """(n, n, n) density: blurred noise (sigma n/12), standardised, through a sigmoid of slope 8 at -0.3."""
    g = gaussian_filter(np.random.default_rng(seed).standard_normal((n, n, n)), n / 12)
    g = (g - g.mean()) / g.std()
    return 1.0 / (1.0 + np.exp(-8.0 * (g + 0.3)))


FIELDS = {"void": void_field, "design": design_field}


SOLVERS = {"V-cycle": (1, 1, False), "W-cycle": (2, 2, False), "W + deflation": (2, 2, True)}
"""Solver variants: (cycle index, coarse-level sweeps, island deflation); the last is the default."""


@contextmanager
def _solver(name: str):
    """Run the ICO term with one of `SOLVERS` (the multigrid module's constants, restored after)."""
    import design.fabrication.multigrid as mg

    saved = mg.CYCLE_INDEX, mg.COARSE_SWEEPS
    mg.CYCLE_INDEX, mg.COARSE_SWEEPS, deflate = SOLVERS[name]
    try:
        yield deflate
    finally:
        mg.CYCLE_INDEX, mg.COARSE_SWEEPS = saved


def _ico_runs(n: int, field: str = "void", deflate: bool = True):
    from design.fabrication.ico import IcoConfig, IcoTerm

    rho = _quadrant(FIELDS[field](n))
    dx = 1.0 / n
    term = IcoTerm(dx, IcoConfig(deflate=deflate))
    t0 = time.perf_counter()
    cold = term.evaluate(rho)
    t_cold = time.perf_counter() - t0
    moved = _step(rho)
    t0 = time.perf_counter()
    warm = term.evaluate(moved)
    t_warm = time.perf_counter() - t0
    return t_cold, t_warm, cold.iterations, warm.iterations


def _peak_memory_child(n: int) -> None:
    _ico_runs(n)
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)  # kB -> MB on Linux


def _coarsening_error(field: str, n: int = 64) -> None:
    from design.fabrication.ico import IcoConfig, incremental_compliance

    rho = _quadrant(FIELDS[field](n))
    start = np.full(rho.shape, float(rho.mean()))
    dx = 1.0 / n
    ref = None
    print(f"coarsening error, {field} field at {n}^3 (quadrant {rho.shape}), J_fab / J_fab(uniform start) and "
          f"gradient against 1 voxel per element:")
    print(f"{'voxels/element':>15} {'J/J0':>9} {'rel. error':>10} {'grad cosine':>11} {'seconds':>8}")
    for c in (1, 2, 4):
        config = IcoConfig(coarsen=c, warm_start=False)
        t0 = time.perf_counter()
        j0 = incremental_compliance(start, dx, config)[0].value
        res = incremental_compliance(rho, dx, config)[0]
        seconds = time.perf_counter() - t0
        ratio, grad = res.value / j0, res.grad / j0
        if ref is None:
            ref = (ratio, grad)
        cosine = float(np.vdot(grad, ref[1]) / (np.linalg.norm(grad) * np.linalg.norm(ref[1])))
        print(f"{c:>15} {ratio:>9.4f} {ratio / ref[0] - 1.0:>10.2%} {cosine:>11.4f} {seconds:>8.2f}")


def _tolerance_error(n: int = 64) -> None:
    from design.fabrication.ico import IcoConfig, incremental_compliance

    print(f"PCG tolerance error at {n}^3: a warm evaluation (as in a design run) against a 1e-10 solve:")
    print(f"{'field':>6} {'tol':>7} {'J rel. error':>12} {'grad rel. error (norm, max)':>28} {'iterations':>10}")
    for field in FIELDS:
        rho = _quadrant(FIELDS[field](n))
        dx = 1.0 / n
        ref = incremental_compliance(rho, dx, IcoConfig(tol=1e-10, warm_start=False))[0]
        for tol in (1e-5, 1e-4, 3e-4, 1e-3):
            warm = incremental_compliance(_step(rho, 2), dx, IcoConfig(tol=tol))[1]
            res = incremental_compliance(rho, dx, IcoConfig(tol=tol), warm=warm)[0]
            err = res.grad - ref.grad
            print(f"{field:>6} {tol:>7.0e} {abs(res.value / ref.value - 1.0):>12.1e} "
                  f"{np.linalg.norm(err) / np.linalg.norm(ref.grad):>13.1e} "
                  f"{np.abs(err).max() / np.abs(ref.grad).max():>14.1e} {res.iterations.sum():>10}")


def _solver_iterations() -> None:
    """PCG iterations per layer, cold and warm, of every solver variant at both sizes."""
    print("PCG iterations per layer by solver (cold | warm; sums in brackets):")
    for field in FIELDS:
        for name in SOLVERS:
            with _solver(name) as deflate:
                for n in (64, 128):
                    _, _, cold, warm = _ico_runs(n, field, deflate)
                    print(f"{field:>6} {name:>14} {n:>4}  {' '.join(map(str, cold))} [{cold.sum()}] | "
                          f"{' '.join(map(str, warm))} [{warm.sum()}]", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="one repeat of the skfmm timing")
    parser.add_argument("--skip-coarsening", action="store_true", help="skip the coarsening- and tolerance-error tables")
    parser.add_argument("--skip-solvers", action="store_true", help="skip the solver variants' iteration table")
    parser.add_argument("--peak-memory-child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.peak_memory_child:
        _peak_memory_child(args.peak_memory_child)
        return

    import skfmm

    from design.forward.simulator import slowness

    repeats = 1 if args.quick else 3
    _ico_runs(16)  # load the compiled kernels outside the timings
    if not args.skip_coarsening:
        for field in FIELDS:
            _coarsening_error(field)
        _tolerance_error()
    if not args.skip_solvers:
        _solver_iterations()
    ratio = {}
    print(f"{'field':>6} {'N':>5} {'skfmm s':>8} {'ico cold s':>10} {'ico warm s':>10} {'cold/skfmm':>10} "
          f"{'warm/skfmm':>10}  PCG iterations per layer (cold | warm)")
    for field in ("design", "void"):
        for n in (64, 128):
            rho = FIELDS[field](n)
            phi = np.pad(np.ones(rho.shape), 1)
            speed = np.pad(1.0 / slowness(rho), 1, constant_values=1.0)
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                skfmm.travel_time(phi, speed, dx=1.0 / n, order=1)
                times.append(time.perf_counter() - t0)
            t_sk = min(times)
            t_cold, t_warm, it_cold, it_warm = _ico_runs(n, field)
            ratio[field, n] = t_warm / t_sk
            print(f"{field:>6} {n:>5} {t_sk:>8.3f} {t_cold:>10.3f} {t_warm:>10.3f} {t_cold / t_sk:>10.2f} "
                  f"{ratio[field, n]:>10.2f}  {' '.join(map(str, it_cold))} | {' '.join(map(str, it_warm))}")
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_ico", "--peak-memory-child", "128"], capture_output=True,
                         text=True, check=True, cwd=ROOT)
    print(f"peak resident memory, ICO cold + warm evaluation at 128^3 (separate process): {float(out.stdout):.0f} MB")
    print(f"ico_over_skfmm_128 = {ratio['void', 128]:.2f}")


if __name__ == "__main__":
    main()
