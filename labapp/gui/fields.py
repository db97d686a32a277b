"""Form fields made from declared settings (:mod:`labapp.acquisition.settings`): a spin box with the setting's
range, unit suffix, decimals, default and help text, read and written in the setting's stored unit."""
from __future__ import annotations

from PySide6.QtWidgets import QDoubleSpinBox, QFormLayout, QWidget

from labapp.acquisition.settings import Setting

_UNBOUNDED = 1e9
"""What an unbounded side of a range becomes in a spin box, in the shown unit."""


class SettingBox(QDoubleSpinBox):
    """A spin box for one setting; :meth:`stored` is the value in the stored unit (None: not given).

    Parameters
    ----------
    setting : Setting
    none_text : str, optional
        For an optional setting: the text shown at the box's lowest value, which means None.
    """

    def __init__(self, setting: Setting, none_text: str | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setting, self.none_text = setting, none_text
        step = 10.0 ** -setting.decimals
        low = -_UNBOUNDED if setting.low is None else setting.shown(setting.low) + (step if setting.low_open else 0.0)
        high = _UNBOUNDED if setting.high is None else setting.shown(setting.high) - (step if setting.high_open else 0.0)
        if none_text is not None:
            low -= step
            self.setSpecialValueText(none_text)
        self.setDecimals(setting.decimals)
        self.setRange(low, high)
        if setting.display_unit:
            self.setSuffix(f" {setting.display_unit}")
        self.setToolTip(setting.help())
        self.set_stored(setting.default)

    def stored(self) -> float | int | None:
        """The value in the setting's stored unit (None at the ``none_text`` value)."""
        if self.none_text is not None and self.value() <= self.minimum():
            return None
        return self.setting.stored(self.value())

    def set_stored(self, value: float | int | None) -> None:
        """Show ``value`` (stored unit; None: the ``none_text`` value, or the lowest value)."""
        self.setValue(self.minimum() if value is None else self.setting.shown(value))


def add_rows(form: QFormLayout, settings: tuple[Setting, ...], none_text: dict[str, str] | None = None,
             ) -> dict[str, SettingBox]:
    """A row per setting (its label, its box) in ``form``; returns the boxes by setting name."""
    boxes = {}
    for setting in settings:
        boxes[setting.name] = SettingBox(setting, (none_text or {}).get(setting.name))
        form.addRow(setting.label, boxes[setting.name])
    return boxes
