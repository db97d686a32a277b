"""The GUI's garbage collector: Python's cyclic collection runs in the GUI thread only."""
import gc
import threading

from labapp.gui.app import gui_thread_garbage_collector


class _Cycle:
    """Cyclic garbage that records the thread that collected it."""

    collected_in: list = []

    def __init__(self):
        self.me = self

    def __del__(self):
        _Cycle.collected_in.append(threading.current_thread().name)


def test_cycles_are_collected_on_the_gui_thread_timer(qtbot):
    collector = gui_thread_garbage_collector()
    try:
        assert not gc.isenabled()

        def allocate_elsewhere():  # a background thread makes garbage well past gc's first threshold
            for _ in range(5 * gc.get_threshold()[0]):
                _Cycle()

        worker = threading.Thread(target=allocate_elsewhere, name="worker")
        worker.start()
        worker.join()
        assert _Cycle.collected_in == []  # nothing collected automatically on the worker
        qtbot.waitUntil(lambda: len(_Cycle.collected_in) > 0, timeout=120_000)
        assert set(_Cycle.collected_in) == {threading.main_thread().name}
    finally:
        collector.timer.stop()
