"""Array work in parts: every index once, the thread count a process is granted, the same values as one pass, and
a forked child that does its own."""
import os
import signal
import time

import numpy as np

from design.forward.release import ramp_release_vjp
from design.inverse.optimize import _cosine_map, _cosine_map_adjoint
from design.threads import MIN_PART, in_parts, thread_count


def test_thread_count_follows_omp_num_threads(monkeypatch):
    # a Dask worker's nanny sets OMP_NUM_THREADS=1: side-by-side designs then use one thread each
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert thread_count() == 3
    monkeypatch.setenv("OMP_NUM_THREADS", "not a number")
    assert thread_count() >= 1
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert thread_count() >= 1


def test_parts_cover_every_index_once(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    for size in (0, 5, MIN_PART, 2 * MIN_PART + 1, 7 * MIN_PART + 3):
        hits = np.zeros(size, dtype=int)
        ranges = []

        def work(i, j, hits=hits, ranges=ranges):
            hits[i:j] += 1
            ranges.append((i, j))

        in_parts(work, size)
        assert np.all(hits == 1)
        assert len(ranges) == max(1, min(3, size // MIN_PART))


def test_release_pullback_and_cosine_map_are_the_same_in_parts(monkeypatch):
    rng = np.random.default_rng(2)
    n = 2 * MIN_PART + 11
    u, length, weight = 3.0 * rng.random(n), 1e-3 + 0.1 * rng.random(n), rng.random(n)
    weight[::7] = 0.0
    u[::13] = 0.0  # steps (a ramp of no length) as well as ramps
    z, g, curve_bar = 3.0 * rng.random(n), rng.standard_normal(n), rng.standard_normal(1001)

    def outputs():
        grad = np.empty(n)
        _cosine_map_adjoint(z, g, grad)
        return [*ramp_release_vjp(u, length, weight, 0.003, curve_bar), _cosine_map(z), grad]

    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    parts = outputs()
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    for split, whole in zip(parts, outputs()):
        assert np.array_equal(split, whole)
    assert np.array_equal(parts[3], 0.5 * (1.0 - np.cos(z)))
    assert np.array_equal(parts[4], 0.5 * (g * np.sin(z)))


def test_a_forked_child_starts_its_own_threads(monkeypatch):
    # the parent's pool threads do not exist in a forked child: work handed to them there would never be done
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    in_parts(lambda i, j: None, 2 * MIN_PART)
    pid = os.fork()
    if pid == 0:  # the child: its exit code says whether every index was done once
        hits = np.zeros(2 * MIN_PART, dtype=int)

        def work(i, j):
            hits[i:j] += 1

        in_parts(work, hits.size)
        os._exit(0 if np.all(hits == 1) else 1)
    deadline = time.monotonic() + 60.0  # only a hung child waits this long
    while (done := os.waitpid(pid, os.WNOHANG))[0] == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    if done[0] == 0:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    assert done[0] == pid and os.waitstatus_to_exitcode(done[1]) == 0
