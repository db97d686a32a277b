"""The run's and the bath's settings as the bench window's forms hold them (the Run tab's
:class:`~labapp.gui.run_controls.RunControls`, the Devices tab's bath): filled from a run config, a method file
(``labapp.acquisition.methods``: what ``sfr method save`` writes and ``sfr run --method`` runs) or the last
session's run, saved as a method file, and locked while a procedure records."""
from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QObject, QSettings, Signal
from PySide6.QtWidgets import QFileDialog, QWidget

from labapp.acquisition.methods import load_method, method_from_config, save_method
from labapp.acquisition.procedures import RunConfig
from labapp.errors import UsageError
from labapp.gui import persist
from labapp.gui.device_panel import DevicePanel
from labapp.gui.run_controls import RunControls


class RunSettings(QObject):
    """The forms' settings as one run's; emits ``message(level, text)`` for the event log.

    Parameters
    ----------
    controls, devices : RunControls, DevicePanel
        The forms: the run's settings and calibration, the bath's.
    data_dir : Path
        Method files are offered in its ``methods`` folder.
    parent : QWidget
        The window: the file dialogs' parent.
    """

    message = Signal(str, str)

    def __init__(self, controls: RunControls, devices: DevicePanel, data_dir: Path, parent: QWidget) -> None:
        super().__init__(parent)
        self.controls, self.devices, self.data_dir = controls, devices, Path(data_dir)

    def apply(self, config: RunConfig, calibration: str, name: bool = True) -> None:
        """Show ``config``'s run and bath settings (not the object's; its name if ``name``) and ``calibration``
        in the forms."""
        self.controls.apply(config, calibration, name)
        self.devices.apply_bath(config.bath)

    def restore(self, settings: QSettings) -> None:
        """The last run's settings, as the previous session left them (:func:`labapp.gui.persist.last_run`)."""
        last = persist.last_run(settings)
        if last is not None:
            self.apply(*last)

    def current(self) -> RunConfig:
        """The run controls' and device panel's settings (UsageError on a bad value)."""
        return self.controls.config(self.devices.bath())

    def set_locked(self, locked: bool) -> None:
        """Make the run's and the bath's settings read-only while a procedure records."""
        self.controls.set_locked(locked)
        self.devices.set_locked(locked)

    def save_method(self, path: str | None = None) -> Path | None:
        """Save the run and bath settings and the calibration as a method file (no ``path``: ask for one)."""
        try:
            config = self.current()
        except Exception as exc:
            self.message.emit("error", f"cannot save the method: {exc}")
            return None
        if not path:
            folder = self.data_dir / "methods"
            folder.mkdir(parents=True, exist_ok=True)
            path, _ = QFileDialog.getSaveFileName(self.parent(), "save method", str(folder / f"{config.name}.json"),
                                                  "method (*.json)")
            if not path:
                return None
        path = Path(path).with_suffix(".json")
        try:
            saved = save_method(method_from_config(path.stem, config, self.controls.calibration_path()), path)
        except UsageError as exc:                    # MethodError, OperatorError: one line naming the problem
            self.message.emit("error", f"cannot save the method: {exc}")
            return None
        self.message.emit("info", f"method saved: {saved}")
        return saved

    def load_method(self, path: str | None = None) -> bool:
        """Fill the forms from a method file (its settings over the defaults, its calibration; no ``path``: ask
        for one)."""
        if not path:
            path, _ = QFileDialog.getOpenFileName(self.parent(), "load method", str(self.data_dir / "methods"),
                                                  "method (*.json)")
            if not path:
                return False
        try:
            method = load_method(Path(path))
            config = method.apply(RunConfig())
        except UsageError as exc:
            self.message.emit("error", str(exc))
            return False
        self.apply(config, method.calibration_file or "", name=False)   # a method names no run
        if method.calibration_file and not Path(method.calibration_file).is_file():
            self.message.emit("warning", f"{path}: its calibration {method.calibration_file} does not exist; "
                              "choose one")
        self.message.emit("info", f"method {method.name!r} loaded: {path}")
        return True
