"""The design launcher's barrier speed: checked, a two-material design run by the CLI's job function, and a
stopped one resumed."""
import json

import pytest

pytest.importorskip("pytestqt")

from types import SimpleNamespace  # noqa: E402

import design.files.twomaterial_outputs as outputs  # noqa: E402
import labapp.jobs.design_barrier as job  # noqa: E402
from design.inverse.twomaterial_problem import TwoMaterialSettings  # noqa: E402
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

    def design_barrier(settings, out, *, resume, on_iteration, should_stop):
        calls.append((settings, out))
        assert not resume
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



def test_a_stopped_two_material_run_resumes_from_the_launcher(qtbot, tmp_path, monkeypatch):
    # a run stopped after its 3rd evaluation (the job sfr design --barrier-speed runs), then Resume... on its folder
    monkeypatch.setattr(outputs, "REFERENCE_MODULE", "design.forward.no_such_module")
    out = tmp_path / "designs" / "delay"
    seen = []
    settings = TwoMaterialSettings(TARGET, 0.25, resolution=16, max_iter=10, stages=2)
    stopped = job.design_barrier(settings, out, on_iteration=lambda k, terms: seen.append(k),
                                 should_stop=lambda: len(seen) >= 3)
    assert stopped.summary is None and not (out / "summary.json").exists()
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    values = []
    launcher.progress.valueChanged.connect(values.append)
    launcher.resume(out)
    assert launcher.busy and launcher.status.text() == f"resuming drug and barrier (barrier speed 0.25) in {out} ..."
    assert not launcher.resume_button.isEnabled() and launcher.stop_button.isEnabled()
    with qtbot.waitSignal(launcher.task.finished, timeout=60_000):
        pass
    assert launcher.status.text().endswith(f"design.stl (drug), barrier.stl and the two-object 3MF in {out}")
    assert min(v for v in values if v > 0) == 4                 # evaluations count on from the checkpoint
    summary = json.loads((out / "summary.json").read_text())
    assert 4 <= summary["evaluations"] <= 10 and (out / "barrier.stl").is_file()
    assert launcher.out_dir == out and launcher.resume_button.isEnabled() and not launcher.stop_button.isEnabled()


def test_resume_of_a_folder_without_a_run_says_so(qtbot, tmp_path):
    folder = tmp_path / "broken"
    folder.mkdir()
    (folder / "config.json").write_text('{"kind": "two-material", "colour": "blue"}')
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    launcher.resume(folder)
    assert launcher.status.text() == "design failed: unknown two-material design settings ['colour']" and not launcher.busy
