"""The "Simulated bench" menu: the simulated bench's faults at the operator's hand, to rehearse them (and for tests
to drive through the window): a busy camera, a corrupt frame, the hotplate's link dropped and back, cold water.

Each action calls a fault hook of :class:`labapp.acquisition.simbench.SimulatedBench` on the bench the window
keeps (built by the first Connect or Start), and says in the event log what it did.
"""
from __future__ import annotations

from collections.abc import Callable

from PySide6.QtWidgets import QMainWindow, QMenu

from labapp.acquisition.simbench import SimulatedBench
from labapp.gui.window_layout import add_menu

COLD_WATER_C = 5.0
"""How much colder the water gets with "cold water poured in", C."""

FAULTS: tuple[tuple[str, Callable[[SimulatedBench], None], str, str], ...] = (
    ("Camera busy (next capture)", lambda sim: sim.camera_busy(1), "the next capture fails as a busy camera's",
     "Ctrl+Shift+B"),
    ("Corrupt frame (next capture)", lambda sim: sim.corrupt_frames(1), "the next frame arrives truncated",
     "Ctrl+Shift+C"),
    ("Drop the hotplate link", lambda sim: sim.drop_hotplate_link(), "the hotplate's serial link is dead until "
     "it is brought back (Simulated bench > Bring the hotplate link back)", "Ctrl+Shift+L"),
    ("Bring the hotplate link back", lambda sim: sim.restore_hotplate_link(), "the hotplate's serial link answers "
     "again", "Ctrl+Shift+R"),
    (f"Cold water poured in (-{COLD_WATER_C:g} C)", lambda sim: sim.cool_bath(COLD_WATER_C),
     f"the water is {COLD_WATER_C:g} C colder", "Ctrl+Shift+W"),
)
"""(menu text, hook, what it does, shortcut) of each fault."""


def add_fault_menu(window: QMainWindow, bench: Callable[[], SimulatedBench | None],
                   say: Callable[[str, str], None]) -> QMenu:
    """Add the "Simulated bench" menu to ``window``: each action injects its fault into ``bench()`` (the kept
    simulated bench; None: none built yet, said through ``say(level, text)``)."""
    def inject(hook: Callable[[SimulatedBench], None], what: str) -> None:
        sim = bench()
        if sim is None:
            say("warning", "no simulated bench yet: Connect (F5) or Start first, then inject a fault")
            return
        hook(sim)
        say("info", f"simulated fault: {what}")
    return add_menu(window, "&Simulated bench",
                    [(text, lambda checked=False, h=hook, w=what: inject(h, w), keys)
                     for text, hook, what, keys in FAULTS])
