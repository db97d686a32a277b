"""One limit per option: the parser refuses what the command would refuse of a single number, and states the
declared range (not a looser sign check followed by the command's narrower one)."""
import pytest

from design.inverse.settings import OPTIONS
from labapp.cli.main import main

NUMBERS = [s for s in OPTIONS if s.kind == "number" and (s.low is not None or s.high is not None)]


def _outside(setting) -> str:
    """A number just outside the setting's range (or an odd one for an even setting)."""
    if setting.even:
        return str(int(setting.low) + 1)
    if setting.low is not None:
        return str(setting.low if setting.low_open else setting.low - (1 if setting.integer else 0.5))
    return str(setting.high + 1)


@pytest.mark.parametrize("setting", NUMBERS, ids=lambda s: s.flag)
def test_the_parser_states_the_declared_range(setting, capsys):
    value = _outside(setting)
    value = str(int(float(value))) if setting.integer else value
    argv = ["design", "--target", "sphere", "--out", "x", setting.flag, *[value] * (setting.count or 1)]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert f"{setting.flag}: '{value}': expected" in err and setting.range_text() in err, err


def test_resolution_one_limit(capsys):
    for value in ("1", "9"):
        with pytest.raises(SystemExit) as exc:
            main(["design", "--target", "sphere", "--out", "x", "--resolution", value])
        assert exc.value.code == 2
        assert f"--resolution: '{value}': expected a whole number >= 8 voxels (even)" in capsys.readouterr().err


@pytest.mark.parametrize("argv, says", [
    (["calibrate-sim", "set.csv", "--out", "x", "--resolution", "2"],
     "--resolution: '2': expected a whole number in [8, 512] voxels"),
    (["compare", "a.csv", "b.csv", "--mtad", "60"], "--mtad: '60': expected a number in (0, 50] %"),
    (["evaluate", "set.csv", "--out", "x", "--resolution", "2"], "--resolution: '2': expected a whole number in [8, 512] voxels"),
])
def test_other_commands_state_their_one_limit(argv, says, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert says in capsys.readouterr().err
