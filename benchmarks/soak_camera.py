"""Soak test: many captures through GPhotoCamera and libgphoto2's virtual Nikon D750.

Feeds a distinct equal-size JPEG into the virtual camera's folder before each capture, checks every
download byte for byte, and reports per-capture time and process memory (this process plus the
libgphoto2 worker, resident set) for the first and the last hundred captures.

    python -m benchmarks.soak_camera [--quick] [--captures N] [--no-configure]

Last line: ``soak_camera_drift_pct: <relative change of the median capture time, last vs first 100>``.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import psutil


def _frame(rng: np.random.Generator, size: int) -> bytes:
    ok, buf = cv2.imencode(".jpg", rng.integers(0, 255, (48, 64, 3)).astype(np.uint8))
    body = buf.tobytes()
    pad = size - len(body) - 4
    if not ok or not 0 <= pad < 65533:
        raise RuntimeError(f"cannot pad a {len(body)}-byte JPEG to {size} bytes")
    return body[:2] + b"\xff\xfe" + (pad + 2).to_bytes(2, "big") + bytes(pad) + body[2:]


def _rss_mib(pids: list[int | None]) -> float:
    total = 0
    for pid in pids:
        if pid is not None:
            try:
                total += psutil.Process(pid).memory_info().rss
            except psutil.NoSuchProcess:
                pass
    return total / 2**20


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="300 captures instead of 2000")
    parser.add_argument("--captures", type=int, help="number of captures (default 2000, 300 with --quick)")
    parser.add_argument("--no-configure", action="store_true",
                        help="skip configure() (the virtual camera then captures ~100x faster)")
    args = parser.parse_args(argv)
    n = args.captures or (300 if args.quick else 2000)
    if n < 200:
        parser.error("--captures must be >= 200 (first and last hundred are compared)")

    work = Path(tempfile.mkdtemp(prefix="soak-camera-"))
    (work / "served").mkdir()
    os.environ.update(VCAMERADIR=str(work / "served"), HOME=str(work), XDG_CONFIG_HOME=str(work))
    from drivers.camera import CameraSettings, GPhotoCamera

    rng = np.random.default_rng(0)
    served = work / "served" / "frame.jpg"
    served.write_bytes(_frame(rng, 6000))
    times, rss, mismatches = [], [], 0
    t_start = time.perf_counter()
    with GPhotoCamera(deadline_s=30.0) as camera:
        if not args.no_configure:
            print("configure:", camera.configure(CameraSettings()))
        for i in range(n):
            frame = _frame(rng, 6000)
            served.write_bytes(frame)
            t0 = time.perf_counter()
            capture = camera.capture()
            times.append(time.perf_counter() - t0)
            mismatches += capture.data != frame
            rss.append(_rss_mib([os.getpid(), camera.worker_pid]))
            if (i + 1) % 100 == 0:
                print(f"{i + 1} captures, median {statistics.median(times[-100:]) * 1e3:.1f} ms, "
                      f"rss {rss[-1]:.1f} MiB", flush=True)
        missed, resets = camera.missed, camera.resets
    first, last = times[:100], times[-100:]
    drift = 100.0 * (statistics.median(last) / statistics.median(first) - 1.0)
    print(f"captures: {n}, wall {time.perf_counter() - t_start:.1f} s, mismatches {mismatches}, "
          f"missed {missed}, resets {resets}")
    print(f"capture time median first 100: {statistics.median(first) * 1e3:.1f} ms, "
          f"last 100: {statistics.median(last) * 1e3:.1f} ms")
    print(f"memory (this process + worker, RSS) mean first 100: {statistics.mean(rss[:100]):.1f} MiB, "
          f"last 100: {statistics.mean(rss[-100:]):.1f} MiB")
    print(f"soak_camera_drift_pct: {drift:.1f}")
    return 1 if mismatches else 0


if __name__ == "__main__":
    sys.exit(main())
