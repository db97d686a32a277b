"""The window's event log pane: one line per event, with a burst of the same warning collapsed into one line.

A driver retrying a dead link logs the same warning every second or two ("reconnect 3 of 5 failed", "link lost
during ..."); shown line by line they push the alarm's own line out of the pane. :class:`EventLog` keeps one line
for a warning that repeats (its text with the numbers taken out) among the last :data:`RECENT` lines: that line
moves to the end with the newest text and a count, ``(x12 since 10:31:05)``. Info lines and errors are never
collapsed.
"""
from __future__ import annotations

import re
import time

from PySide6.QtGui import QTextCursor
from PySide6.QtWidgets import QPlainTextEdit, QWidget

MAX_LINES = 2000
"""Lines kept in the pane (older ones scroll away)."""
RECENT = 8
"""A warning repeating one of the last this many lines replaces it."""
_NUMBERS = re.compile(r"\d+(\.\d+)?")


def kind_of(level: str, message: str) -> str:
    """What makes two messages "the same" for collapsing: their level and their text without its numbers."""
    return f"{level}:{_NUMBERS.sub('#', message)}"


class EventLog(QPlainTextEdit):
    """A read-only log pane; :meth:`add` appends a line, collapsing repeated warnings (see the module)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setReadOnly(True)
        self.setMaximumBlockCount(MAX_LINES)
        self._tail: list[tuple[str, int, str]] = []         # the last lines: (kind, count, time of the first)

    def add(self, level: str, message: str) -> None:
        """Append ``message`` at ``level`` (info, warning, error)."""
        bar = self.verticalScrollBar()
        at_end = bar.value() >= bar.maximum() - 2            # follow the newest line unless scrolled back
        line, kind = f"{level.upper():7s} {message}", kind_of(level, message)
        count, first = 1, time.strftime("%H:%M:%S")
        kinds = [k for k, _, _ in self._tail]
        if level == "warning" and kind in kinds:
            back = len(kinds) - 1 - kinds[::-1].index(kind)
            _, count, first = self._tail.pop(back)
            count += 1
            block = self.document().findBlockByNumber(self.document().blockCount() - (len(kinds) - back))
            cursor = QTextCursor(block)
            cursor.select(QTextCursor.SelectionType.BlockUnderCursor)
            if block.blockNumber() == 0:             # the first line: take its line break instead
                cursor.movePosition(QTextCursor.MoveOperation.NextCharacter, QTextCursor.MoveMode.KeepAnchor)
            cursor.removeSelectedText()
            line += f"  (x{count} since {first})"
        self.appendPlainText(line)
        self._tail.append((kind, count, first))
        del self._tail[:-RECENT]
        if at_end:
            bar.setValue(bar.maximum())
