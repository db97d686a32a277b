"""Waiting for a recording `sfr run` process's frames, for the tests that act on a run while it records."""
import time

from labapp.records.manifests import read_run


def wait_frames(root, n, proc, timeout_s=300):
    """The run folder under ``root`` once it holds at least ``n`` frames; fails if ``proc`` ends first."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        assert proc.poll() is None, proc.stdout.read()
        folders = [p for p in root.glob("*") if (p / "frames.csv").exists()]
        if folders and len(read_run(folders[0]).frames) >= n:
            return folders[0]
        time.sleep(0.05)
    raise AssertionError(f"fewer than {n} frames after {timeout_s} s")
