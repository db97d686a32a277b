"""`sfr demo --seed N`: the loop on another hidden material, drawn from the seed (the default: the demo's own)."""
import pytest

from labapp.acquisition.simbench import Material
from labapp.cli.main import main
from labapp.errors import UsageError
from labapp.jobs import demo


@pytest.mark.parametrize(("argv", "expected"), [([], None), (["--seed", "11"], Material.draw(11))])
def test_the_seed_draws_the_benchs_hidden_material(tmp_path, monkeypatch, capsys, argv, expected):
    seen = {}

    def stop(out, **kwargs):
        seen.update(kwargs)
        raise UsageError("stopped before the loop")

    monkeypatch.setattr(demo, "run_demo", stop)
    assert main(["demo", "--out", str(tmp_path / "demo"), *argv]) == 2
    assert seen["material"] == expected
    assert "stopped before the loop" in capsys.readouterr().err


def test_a_seed_that_is_not_a_whole_number_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["demo", "--out", str(tmp_path / "demo"), "--seed", "eleven"])
    assert stop.value.code == 2
    assert "--seed" in capsys.readouterr().err
    assert not (tmp_path / "demo").exists()
