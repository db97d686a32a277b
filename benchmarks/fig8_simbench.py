"""Paper Fig. 8 on the simulated bench: measured vs forward model (leave-one-out) vs Monte Carlo.

Records a calibration set on the simulated bench (a bench calibration series, then one release run per
sample object in the bench's hidden material, a frame a minute), writes its ``calibration_set.csv`` and
runs ``sfr evaluate``'s job on it. The table and picture go into ``docs/science.md`` and
``docs/figures/``.

    flock /tmp/sfr-heavy.lock .venv/bin/python -m benchmarks.fig8_simbench --out /tmp/fig8 [--resolution 48]
"""
from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

SHAPES = ("sphere", "pill", "spinner_top", "csg", "polyhedron")
"""The five objects of the set, as in section 5.1 (five shapes of about the same mass)."""


def record_set(out: Path, interval_s: float) -> tuple[Path, Path]:
    """Bench calibration and one run per shape on the simulated bench; returns (set.csv, bench calibration)."""
    from design.geometry.shapes import sample_shape
    from labapp.acquisition.clock import SteppedClock
    from labapp.acquisition.simbench import Material, sample_release
    from labapp.jobs.demo import TRUTH_RESOLUTION, simulated_calibration, simulated_run

    clock = SteppedClock()
    calibration, cal_path = simulated_calibration(out / "calibration", clock)
    material = Material.draw()
    (out / "meshes").mkdir(parents=True, exist_ok=True)
    rows = ["run,mesh,object_mass_g"]
    for index, shape in enumerate(SHAPES):
        release = sample_release(shape, index=index, resolution=TRUTH_RESOLUTION, material=material)
        sample_shape(shape).export(out / "meshes" / f"{shape}.stl")
        run = simulated_run(clock, calibration, release, out / "runs", interval_s=interval_s, hotplate=False)
        rows.append(f"{run.relative_to(out)},meshes/{shape}.stl,")
        print(f"  {shape}: {release.mass_g:.3f} g, {release.duration_s / 3600:.2f} h -> {run.name}", flush=True)
    set_csv = out / "calibration_set.csv"
    set_csv.write_text("\n".join(rows) + "\n")
    return set_csv, cal_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--resolution", type=int, default=48)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--interval", type=float, default=60.0, help="frame interval of the runs, s")
    parser.add_argument("--docs", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "figures")
    args = parser.parse_args()
    from labapp.jobs.evaluate import evaluate_models, markdown_table

    start = time.perf_counter()
    if (args.out / "set").exists():
        raise SystemExit(f"{args.out / 'set'} exists; choose a new --out")
    print(f"recording the calibration set in {args.out / 'set'} ...", flush=True)
    set_csv, cal_path = record_set(args.out / "set", args.interval)
    print(f"set ready ({time.perf_counter() - start:.0f} s); evaluating ...", flush=True)
    result = evaluate_models(set_csv, cal_path, args.out / "evaluation", resolution=args.resolution,
                             seeds=args.seeds, progress=lambda f, m: print(f"[{100 * f:3.0f}%] {m}", flush=True))
    print(markdown_table(result.doc))
    args.docs.mkdir(parents=True, exist_ok=True)
    shutil.copy(result.out / "evaluation.png", args.docs / "fig8_simbench.png")
    print(f"done in {time.perf_counter() - start:.0f} s; picture -> {args.docs / 'fig8_simbench.png'}")


if __name__ == "__main__":
    main()
