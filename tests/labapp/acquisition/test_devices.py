"""Devices: a missing camera or port is one operator-readable line with no run folder left; `sfr devices
--probe` sends only read-only queries until (and after) the device answered as a Heidolph; the emulator
cleans up on SIGTERM as on Ctrl-C."""
import os
import signal
import subprocess
import sys

from drivers.hotplate import heidolph
from labapp.cli.main import main
from tests.drivers.scripted_port import ScriptedPort

QUERIES = [(b"IN_PV_1\r\n", b"IN_PV_1 999.9\n\r"), (b"IN_PV_3\r\n", b"IN_PV_3 21.5\n\r"),
           (b"IN_PV_5\r\n", b"IN_PV_5 0\n\r"), (b"IN_SP_1\r\n", b"IN_SP_1 70.0\n\r"),
           (b"IN_SP_3\r\n", b"IN_SP_3 150\n\r")]


def _probe(monkeypatch, pairs, capsys) -> tuple[int, str]:
    port = ScriptedPort(pairs)            # any write not in `pairs` (PA_NEW, CC_ON, STOP_1 ...) fails the test
    monkeypatch.setattr(heidolph.serial, "serial_for_url", lambda url, **kw: port)
    monkeypatch.setattr(heidolph.time, "sleep", lambda s: None)
    monkeypatch.setattr("drivers.camera.detect_cameras", lambda deadline_s: [])
    monkeypatch.setattr("drivers.camera.usb.list_cameras", lambda: [])
    code = main(["devices", "--probe", "scripted"])
    assert not port.pairs
    return code, capsys.readouterr().out


def test_probe_sends_only_queries_to_a_heidolph(monkeypatch, capsys):
    code, out = _probe(monkeypatch, QUERIES, capsys)
    assert code == 0
    assert "Heidolph reply: plate 21.5 C, probe no probe, 0 rpm, setpoints 70.0 C / 150 rpm" in out


def test_probe_of_another_device_stops_after_the_first_query(monkeypatch, capsys):
    code, out = _probe(monkeypatch, [(b"IN_PV_1\r\n", b"OK\r\n")], capsys)
    assert code == 1 and "did not answer 'IN_PV_1' as a Heidolph MR Hei-Tec does" in out


def test_missing_camera_is_one_line_and_leaves_no_run_folder(tmp_path, capsys):
    data = tmp_path / "data"
    code = main(["run", "--camera", f"folder:{tmp_path / 'no-card'}", "--out", str(data), "--max-hours", "0.01"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert "run failed: camera folder" in err and "does not exist" in err and "(no run folder written)" in err
    assert not data.exists() or not any(data.iterdir())


def test_missing_hotplate_port_is_one_line(tmp_path, capsys):
    cards = tmp_path / "card"
    cards.mkdir()
    code = main(["run", "--camera", f"folder:{cards}", "--hotplate", str(tmp_path / "ttyNONE"),
                 "--out", str(tmp_path / "data"), "--max-hours", "0.01"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1 and "cannot open hotplate port" in err
    assert not (tmp_path / "data").exists()                  # nothing made before the devices answer


def test_emulator_cleans_up_on_sigterm(tmp_path):
    env = dict(os.environ, HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path))
    emu = subprocess.Popen([sys.executable, "-m", "labapp.cli.main", "emulate", "heidolph", "--seed", "0"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    try:
        path = emu.stdout.readline().strip()
        assert os.path.exists(path)
        emu.send_signal(signal.SIGTERM)
        assert emu.wait(timeout=120) == 130
        assert not os.path.exists(path)
    finally:
        emu.kill()
