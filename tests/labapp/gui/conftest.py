"""GUI tests keep the application's settings in a temporary INI file, never the user's."""
import pytest

from labapp.gui.persist import SETTINGS_ENV


@pytest.fixture(autouse=True)
def _settings_file(tmp_path, monkeypatch):
    monkeypatch.setenv(SETTINGS_ENV, str(tmp_path / "sfr-lab.ini"))
