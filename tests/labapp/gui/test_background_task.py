"""A background task is done when its result reaches the GUI thread, not when its thread ends."""
import threading

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QObject  # noqa: E402

from labapp.gui.bridge import BackgroundTask  # noqa: E402


class _HeldTask(BackgroundTask):
    """A task whose thread stays alive after it emitted its result, until released."""

    def __init__(self, fn):
        super().__init__(fn)
        self.release = threading.Event()

    def _run(self):
        super()._run()
        self.release.wait(60)


class _Receiver(QObject):
    """Records, in the GUI thread, whether the task still said it was running when its result arrived."""

    def __init__(self, task):
        super().__init__()
        self.task, self.seen = task, []
        task.finished.connect(self.result)
        task.failed.connect(self.error)

    def result(self, value):
        self.seen.append(("finished", value, self.task.running))

    def error(self, message):
        self.seen.append(("failed", message, self.task.running))


@pytest.mark.parametrize("fails", [False, True])
def test_a_task_is_not_running_once_its_result_is_delivered(qtbot, fails):
    def work(progress):
        if fails:
            raise ValueError("bad input")
        return 42

    task = _HeldTask(work)
    receiver = _Receiver(task)
    assert not task.running
    task.start()
    try:
        qtbot.waitUntil(lambda: bool(receiver.seen), timeout=60_000)
        assert task._thread.is_alive()        # its thread has not returned yet
        assert receiver.seen == [("failed", "ValueError: bad input", False) if fails else ("finished", 42, False)]
        assert not task.running
    finally:
        task.release.set()
