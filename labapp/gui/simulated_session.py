"""The simulated bench of a bench-window session: built for the bath's water, kept until the water changes,
closed when it is replaced or the window closes.

Building one takes seconds: its sample's release (the object's dissolution) is computed once a session, in a
child process (:func:`release_in_subprocess`), and a new bench opens the Heidolph emulator on a pseudo-terminal.
The window builds it in a worker thread (:meth:`SimulatedSession.build`) and keeps it in the GUI thread
(:meth:`SimulatedSession.keep`). No Qt import.
"""
from __future__ import annotations

import multiprocessing
import threading
from concurrent.futures import ProcessPoolExecutor

from drivers.hotplate.base import Hotplate
from labapp.acquisition.clock import Clock
from labapp.acquisition.simbench import SampleRelease, SimulatedBench, sample_release
from labapp.gui.plate_poller import IdlePlatePoller

_RELEASES: dict[str, SampleRelease] = {}
"""Simulated samples' releases computed in this process's lifetime (the same object dissolves the same way)."""


def release_in_subprocess(sample: str) -> SampleRelease:
    """The simulated sample's release, computed once in a child process: its fast marching (scikit-fmm) holds
    the GIL for seconds, which in a thread of this process would freeze the window all the same."""
    if sample not in _RELEASES:
        with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
            _RELEASES[sample] = pool.submit(sample_release, sample).result()
    return _RELEASES[sample]


class SimulatedSession:
    """The simulated bench a window keeps between procedures.

    Parameters
    ----------
    sample : str
        The simulated bench's sample object.
    poller : IdlePlatePoller
        The window's idle poller: it lets go of an old bench's hotplate before that bench closes.
    """

    def __init__(self, sample: str, poller: IdlePlatePoller) -> None:
        self.sample, self.poller = sample, poller
        self.bench: SimulatedBench | None = None
        """The bench kept for the next procedure (None: none built yet, or released)."""
        self.release: SampleRelease | None = None
        """The sample's release once computed: every later bench of the session dissolves it."""

    def fits(self, water_g: float) -> bool:
        """True when the kept bench holds ``water_g`` g of water (the next procedure may use it)."""
        return self.bench is not None and self.bench.scene.water_g == water_g

    def build(self, water_g: float, with_hotplate: bool, clock: Clock) -> SimulatedBench:
        """A new bench with ``water_g`` g of water on ``clock`` (seconds: call it off the GUI thread); it is not
        kept until :meth:`keep`."""
        release = self.release or release_in_subprocess(self.sample)
        return SimulatedBench(clock, release=release, sample=self.sample, with_hotplate=with_hotplate,
                              water_g=water_g)

    def keep(self, bench: SimulatedBench | None, polled: Hotplate | None) -> bool:
        """Keep ``bench`` (None: none; the next is built anew) and its sample's release; close the one kept so far.

        Parameters
        ----------
        bench : SimulatedBench or None
            The bench to keep.
        polled : Hotplate or None
            The hotplate the window's idle poller holds.

        Returns
        -------
        bool
            True when ``polled`` was the old bench's: the poller lets go of it and the bench closes in a thread
            of its own (up to a poll and a close), and the window stops polling it.
        """
        if bench is not None:
            self.release = bench.release
        old, self.bench = self.bench, bench
        if old is None or old is bench:
            return False
        if old.hotplate is not None and old.hotplate is polled:
            threading.Thread(target=_release_then_close, args=(self.poller, old), name="old-bench",
                             daemon=True).start()
            return True
        old.close()
        return False


def _release_then_close(poller: IdlePlatePoller, bench: SimulatedBench) -> None:
    poller.release(bench.hotplate)
    bench.close()
