"""`sfr emulate heidolph` prints its device path first; `sfr devices --probe` finds the plate there."""
import os
import signal
import subprocess
import sys


def test_emulate_then_probe_then_ctrl_c(tmp_path):
    env = dict(os.environ, HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path))
    env.pop("VCAMERADIR", None)
    emu = subprocess.Popen([sys.executable, "-m", "labapp.cli.main", "emulate", "heidolph", "--seed", "0"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    try:
        path = emu.stdout.readline().strip()
        assert path.endswith("/tty") and os.path.exists(path)
        out = subprocess.run([sys.executable, "-m", "labapp.cli.main", "devices", "--probe", path],
                             capture_output=True, text=True, timeout=300, env=env)
        assert out.returncode == 0, out.stderr
        assert f"probe {path}: Heidolph reply: plate 2" in out.stdout
        emu.send_signal(signal.SIGINT)
        assert emu.wait(timeout=120) == 130                  # Ctrl-C ends every command with 130
        assert not os.path.exists(path)
    finally:
        emu.kill()


def test_probe_of_a_missing_port_fails_clearly(tmp_path):
    env = dict(os.environ, HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path))
    out = subprocess.run([sys.executable, "-m", "labapp.cli.main", "devices", "--probe", str(tmp_path / "ttyX")],
                         capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 1
    assert "no Heidolph reply: cannot open hotplate port" in out.stdout
