"""Per-frame analysis time of a D750-size JPEG against a plain full decode, and offline throughput.

    .venv/bin/python -m benchmarks.bench_analysis [--quick] [--reduce 4]

Renders a 6016 x 4016 bench frame (the Nikon D750's size, JPEG quality 95) with drivers.sim, then in
the same process times

- ``cv2.imread`` of the file at full size (the baseline);
- ``analysis.read_cells`` of the same file (decode with ``--reduce``, crop + mirror, 10x10 cells);
- the cell values at reduce 2/4/8 against reduce 1 (what downscaled decoding costs in accuracy);
- ``analysis.analyze_run`` on a folder of copies with one thread and with all cores (frames per second).

Timings are medians of repeated runs. The last line is ``analysis_over_imread: <ratio>``.
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from analysis import CropGeometry, analyze_run, fit_bench_calibration, read_cells
from drivers.sim.bench_scene import BenchScene, render_jpeg


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats and frames")
    parser.add_argument("--reduce", type=int, default=4, choices=(1, 2, 4, 8), help="decode downscaling (default 4)")
    args = parser.parse_args()
    repeats, n_frames = (3, 8) if args.quick else (9, 40)
    cv2.setNumThreads(1)  # per-frame figures on one core; throughput below uses a thread per core

    scene = BenchScene(width=6016, height=4016)
    geometry = CropGeometry(*scene.default_crop())
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        levels = (0.0, 1.75, 3.5)
        cal_files = []
        for i, conc in enumerate(levels):
            cal_files.append(folder / f"cal_{i}.jpg")
            cal_files[-1].write_bytes(render_jpeg(scene, conc, 0.0, rng, quality=95))
        frame = cal_files[1]
        print(f"frame: {scene.width}x{scene.height} px JPEG q95, {frame.stat().st_size / 1e6:.2f} MB; "
              f"crop {geometry.size} px, {geometry.grid}x{geometry.grid} cells")

        t_imread = _median_time(lambda: cv2.imread(str(frame), cv2.IMREAD_COLOR), repeats)
        per_reduce = {r: _median_time(lambda r=r: read_cells(frame, geometry, reduce=r), repeats) for r in (1, 2, 4, 8)}
        print(f"cv2.imread full size: {1000 * t_imread:.1f} ms")
        full = read_cells(frame, geometry)
        for r, t in per_reduce.items():
            diff = np.abs(read_cells(frame, geometry, reduce=r) / full - 1)
            print(f"read_cells reduce={r}: {1000 * t:.1f} ms = {t / t_imread:.3f} x imread; cell values vs reduce=1: "
                  f"max {100 * diff.max():.3f} %, mean {100 * diff.mean():.4f} %")

        cells = np.array([read_cells(f, geometry, reduce=args.reduce) for f in cal_files])
        cal = fit_bench_calibration(cells, np.array(levels), geometry, scene.water_g,
                                    image_shape=(scene.height, scene.width), reduce=args.reduce)
        run = folder / "run"
        run.mkdir()
        lines = ["file,t_s"]
        for i in range(n_frames):
            shutil.copy(frame, run / f"f{i:04d}.jpg")
            lines.append(f"f{i:04d}.jpg,{11.0 * i}")
        (run / "frames.csv").write_text("\n".join(lines) + "\n")
        cores = os.cpu_count() or 1
        for workers in sorted({1, cores}):
            start = time.perf_counter()
            analyze_run(run, cal, workers=workers)
            elapsed = time.perf_counter() - start
            print(f"analyze_run {n_frames} frames, {workers} thread(s): {elapsed:.2f} s = {n_frames / elapsed:.2f} frames/s")
    print(f"analysis_over_imread: {per_reduce[args.reduce] / t_imread:.3f}")


if __name__ == "__main__":
    main()
