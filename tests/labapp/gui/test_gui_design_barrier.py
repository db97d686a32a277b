"""The design launcher's barrier speed: checked, and a two-material design run by the CLI's job function."""
import pytest

pytest.importorskip("pytestqt")

from types import SimpleNamespace  # noqa: E402

import labapp.jobs.design_barrier as job  # noqa: E402
from labapp.gui.design_launcher import DesignLauncher  # noqa: E402

TARGET = "delay-zero:delay=1,rate=2,volume=3"


@pytest.mark.parametrize("speed, target, message", [
    ("-1", TARGET, "barrier: barrier speed must be finite and >= 0 (0: insoluble), got -1"),
    ("fast", TARGET, "barrier: barrier speed must be a number, got 'fast'"),
    ("0.5", "sphere", "sphere: a two-material design takes delay-zero:, pulses:, constant: or a tau_mm,released_mm3 CSV"),
])
def test_a_bad_barrier_or_target_is_refused_before_any_work(qtbot, tmp_path, monkeypatch, speed, target, message):
    monkeypatch.setattr(job, "design_barrier", lambda *a, **k: pytest.fail("designed"))
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    launcher.source.setText(target)
    launcher.barrier_speed.setText(speed)
    launcher.start()
    assert launcher.status.text() == message and not launcher.busy
    assert not (tmp_path / "designs").exists()


def test_the_ico_space_is_refused_for_two_materials(qtbot, tmp_path):
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    launcher.source.setText(TARGET)
    launcher.barrier_speed.setText("0.5")
    launcher.space.setCurrentText("ico")
    launcher.start()
    assert launcher.status.text().startswith("barrier: two-material design: space = 'ico'") and not launcher.busy


def test_the_barrier_speed_runs_the_two_material_design(qtbot, tmp_path, monkeypatch):
    calls = []

    def design_barrier(settings, out, *, on_iteration, should_stop):
        calls.append((settings, out))
        on_iteration(1, {"J": 0.5, "J_fit": 0.25})
        return SimpleNamespace(status="converged", out=out, summary={})
    monkeypatch.setattr(job, "design_barrier", design_barrier)
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    launcher.source.setText(TARGET)
    launcher.barrier_speed.setText("0.25")
    launcher.start()
    qtbot.waitUntil(lambda: "two-material design converged" in launcher.status.text(), timeout=10_000)
    (settings, out), = calls
    assert settings.barrier_speed == 0.25 and settings.target == TARGET and settings.space == launcher.settings()["space"]
    assert out == launcher.out_dir and launcher.start_button.isEnabled() and not launcher.stop_button.isEnabled()
