"""Form fields made from declared settings (:mod:`labapp.acquisition.settings`, and the design settings of
:mod:`design.inverse.settings`): a spin box with the setting's unit suffix, decimals, default and help text, read and
written in the setting's stored unit; for a design setting with choices a combo box, for a switch a check box
(:func:`setting_field`).

A box accepts any number as typed and says in the field when it is outside the setting's range (never
clamping it silently: ``-20`` stays ``-20`` and is refused, ``3000`` is not cut to ``30``); forms keep
their action disabled while :meth:`SettingBox.problem` names what is wrong.
"""
from __future__ import annotations

from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout, QLabel, QWidget

from labapp.acquisition.settings import Setting

_UNBOUNDED = 1e9
"""The box's own limits, in the shown unit: far outside any setting's range, so that a typed value is kept
and checked against the range instead of being cut to it by the box."""
_INVALID_STYLE = "background-color: #ffd0d0;"


class SettingBox(QDoubleSpinBox):
    """A spin box for one setting; :meth:`stored` is the value in the stored unit (None: not given).

    Emits ``problem_changed(text)`` when the value becomes allowed (``""``) or not (what is wrong).

    Parameters
    ----------
    setting : Setting or design.inverse.settings.DesignSetting
    none_text : str, optional
        For an optional setting: the text shown at the box's lowest value, which means None ("not
        weighed", "no heating"); stepping down from the range's low end reaches it.
    """

    problem_changed = Signal(str)

    def __init__(self, setting: Setting | Any, none_text: str | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setting, self.none_text = setting, none_text
        self.setDecimals(setting.decimals)
        self.setRange(-_UNBOUNDED, _UNBOUNDED)
        if getattr(setting, "even", False):
            self.setSingleStep(2)
        if none_text is not None:
            self.setSpecialValueText(none_text)
        if setting.display_unit:
            self.setSuffix(" \u00b0C" if setting.display_unit == "C" else f" {setting.display_unit}")   # degrees shown
        self.setKeyboardTracking(True)
        self._problem: str | None = None
        self.error_label = QLabel("")
        """Where a form shows :meth:`problem` under the box (see :func:`add_rows`)."""
        self.error_label.setStyleSheet("color: #b00000;")
        self.error_label.setWordWrap(True)
        self.error_label.hide()
        self.valueChanged.connect(self._check)
        self.set_stored(setting.default)
        self._check()

    # -- values -----------------------------------------------------------------------------------------------
    def is_none(self) -> bool:
        """True at the ``none_text`` value."""
        return self.none_text is not None and self.value() <= self.minimum()

    def stored(self) -> float | int | None:
        """The value in the setting's stored unit (None at the ``none_text`` value); not checked, see
        :meth:`problem`."""
        if self.is_none():
            return None
        return self.setting.stored(self.value())

    def set_stored(self, value: float | int | None) -> None:
        """Show ``value`` (stored unit; None: the ``none_text`` value, or the range's low end)."""
        if value is None:
            self.setValue(self.minimum() if self.none_text is not None else self._low_shown())
        else:
            self.setValue(self.setting.shown(value))

    def problem(self) -> str:
        """What is wrong with the value, in one line naming the setting, the value and the allowed range
        (``""``: allowed)."""
        if self.is_none():
            return ""
        value = self.value()
        stored = self.setting.stored(value)
        if self.setting.allows(stored) and not (self.setting.integer and value != int(value)):
            return ""
        unit = f" {self.setting.display_unit}" if self.setting.display_unit else ""
        kind = "a whole number " if self.setting.integer and not self.setting.choices else ""
        return f"{self.setting.label} must be {kind}{self.setting.range_text(shown=True)}, got {value:g}{unit}"

    # -- behaviour ------------------------------------------------------------------------------------------------
    def _low_shown(self) -> float:
        s = self.setting
        if s.low is None:
            return 0.0
        return s.shown(s.low) + (10.0 ** -s.decimals if s.low_open else 0.0)

    def stepBy(self, steps: int) -> None:  # noqa: N802 (Qt override)
        """Arrow keys: from the ``none_text`` value up to the range's low end, and below it down to
        ``none_text``; otherwise the usual steps."""
        if self.none_text is not None:
            low = self._low_shown()
            if self.is_none() and steps > 0:
                self.setValue(low)
                return
            if not self.is_none() and steps < 0 and self.value() + steps * self.singleStep() < low:
                self.setValue(self.minimum())
                return
        super().stepBy(steps)

    def _check(self, *_args) -> None:
        problem = self.problem()
        if problem == self._problem:
            return
        self._problem = problem
        self.setStyleSheet(_INVALID_STYLE if problem else "")
        self.setToolTip(f"{problem}\n\n{self.setting.help()}" if problem else self.setting.help())
        self.error_label.setText(problem)
        self.error_label.setVisible(bool(problem) and self.error_label.parentWidget() is not None)  # once in a form
        self.problem_changed.emit(problem)

    def add_to(self, form: QFormLayout, label: str) -> None:
        """Add a row ``label``: the box to ``form``, and under it the box's error line."""
        form.addRow(label, self)
        form.addRow(self.error_label)
        self.error_label.setVisible(bool(self._problem))


def narrow_form(parent: QWidget | None = None) -> QFormLayout:
    """A form whose rows put a field under its label when the form is too narrow for both side by side, so
    that a form in the bench dock never needs a horizontal scroll bar."""
    form = QFormLayout(parent)
    form.setRowWrapPolicy(QFormLayout.RowWrapPolicy.WrapLongRows)
    return form


def add_rows(form: QFormLayout, settings: tuple[Setting, ...], none_text: dict[str, str] | None = None,
             ) -> dict[str, SettingBox]:
    """A row per setting (its label, its box, and under it the box's error line) in ``form``; returns the
    boxes by setting name."""
    boxes = {}
    for setting in settings:
        box = SettingBox(setting, (none_text or {}).get(setting.name))
        boxes[setting.name] = box
        box.add_to(form, setting.label)
    return boxes


def setting_field(setting: Any, parent: QWidget | None = None) -> QWidget:
    """The form field of a declared design setting (:class:`design.inverse.settings.DesignSetting`) at its default,
    with its help text as tooltip: a :class:`SettingBox` for a number, a combo box of its choices for a text, a check
    box labelled with the setting for a switch."""
    if setting.kind == "number":
        return SettingBox(setting, parent=parent)
    if setting.kind == "switch":
        field = QCheckBox(setting.label, parent)
        field.setChecked(bool(setting.default))
    else:
        field = QComboBox(parent)
        field.addItems([str(c) for c in setting.choices])
        field.setCurrentText(str(setting.default))
    field.setToolTip(setting.help())
    return field


def problems(boxes: dict[str, SettingBox] | list[SettingBox]) -> list[str]:
    """The problems of the boxes that have one, in order."""
    items = boxes.values() if isinstance(boxes, dict) else boxes
    return [p for p in (box.problem() for box in items) if p]
