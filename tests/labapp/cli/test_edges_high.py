"""The command line at its edges (issue 45, severe and high): a full disk, curves in the wrong unit, results
written over, checks made after the work instead of before, exit codes that disagree."""
from labapp.cli.main import main
from labapp.errors import EXIT_FAILED
from labapp.records.audit import AUDIT_FILE
from labapp.records.runrecord import RecordStatus
from labapp.records.storage import create_run


def _finished_run(tmp_path):
    run = create_run(tmp_path / "data", "pill", {"simulated": True, "object_mass_g": 2.0, "water_g": 500.0,
                                                  "interval_s": 300.0})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    return run.path


def test_audit_fails_a_trail_cut_off_at_its_end_with_verifys_exit_code(tmp_path, capsys):
    folder = _finished_run(tmp_path)
    trail = folder / AUDIT_FILE
    trail.write_bytes(trail.read_bytes().splitlines(keepends=True)[0])      # the 'complete' entry cut off
    assert main(["verify", str(folder)]) == EXIT_FAILED
    assert main(["audit", str(folder)]) == EXIT_FAILED
    out = capsys.readouterr().out
    assert "chain BROKEN" in out and "TRUNCATED" in out


def test_method_save_refuses_a_released_range_upside_down_naming_the_option(tmp_path, capsys):
    import pytest

    from labapp.acquisition.methods import Criterion, MethodError
    from labapp.errors import EXIT_USAGE

    folder = _finished_run(tmp_path)
    out = tmp_path / "m.json"
    with pytest.raises(SystemExit) as exc:
        main(["method", "save", str(out), "--from", str(folder), "--accept-released", "1:80:40"])
    assert exc.value.code == EXIT_USAGE
    err = capsys.readouterr().err
    assert "--accept-released" in err and "LOW 80 % is above HIGH 40 %" in err
    assert not out.exists()
    with pytest.raises(MethodError, match="low 80 is above high 40"):
        Criterion("released_percent", 80.0, 40.0, 1.0)


def test_the_status_line_away_from_a_terminal_is_a_line_per_step_or_minute(capsys):
    from labapp.acquisition.events import FrameStored
    from labapp.acquisition.status import RunStatus
    from labapp.cli.drive import LOG_EVERY_S, _status_printer

    status, clock = RunStatus(), [0.0]
    show = _status_printer(status, tty=False, now=lambda: clock[0])
    for _ in range(100):                    # 25 s of refreshes, nothing new: one line
        show()
        clock[0] += 0.25
    status.update(FrameStored(index=0, file="frame_000000.jpg", path="frame_000000.jpg", t_s=30.0, n_frames=1))
    show()                                  # a step: a line
    clock[0] += LOG_EVERY_S
    show()                                  # a minute: a line
    out = capsys.readouterr().out
    assert "\r" not in out and out.count("\n") == 3
    assert "frames 1" in out.splitlines()[1]


def test_a_series_with_too_few_masses_is_refused_before_the_bath_heats(tmp_path, capsys):
    from labapp.errors import EXIT_USAGE

    runs = tmp_path / "runs"
    assert main(["calibrate-bench", "--record", str(runs), "--simulate", "--speed", "0", "--masses", "1"]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "--masses" in err and "needs 3" in err
    assert not runs.exists() or not any(runs.iterdir())


def _curve(path, factor=1.0, nan_row=None):
    """A 4 h first-order release of 2 g every 5 min; times divided by ``factor`` (3600: hours, 60: minutes)."""
    import numpy as np

    t = np.arange(0.0, 4 * 3600.0 + 1, 300.0)
    grams = 2.0 * (1 - np.exp(-3e-4 * t))
    rows = [f"{a / factor:g},{'nan' if i + 1 == nan_row else f'{b:.6f}'}" for i, (a, b) in enumerate(zip(t, grams))]
    path.write_text("t_s,released_g\n" + "\n".join(rows) + "\n")
    return path


def test_report_refuses_a_curve_in_hours_or_with_a_nan_before_writing(tmp_path, capsys):
    from labapp.errors import EXIT_USAGE

    folder = _finished_run(tmp_path)
    out = tmp_path / "r.pdf"
    for curve, says in ((_curve(tmp_path / "hours.csv", 3600.0), "hours.csv: t_s ends at 4, a release over 4 s"),
                        (_curve(tmp_path / "nan.csv", nan_row=7), "nan.csv: row 7: released_g = nan is not a finite")):
        assert main(["report", str(folder), "--curve", str(curve), "--out", str(out)]) == EXIT_USAGE
        assert says in capsys.readouterr().err and not out.exists()
    assert main(["report", str(folder), "--curve", str(_curve(tmp_path / "good.csv")), "--out", str(out)]) == 0


def test_compare_names_the_curve_in_hours_in_either_order(tmp_path, capsys):
    from labapp.errors import EXIT_USAGE

    good, hours = _curve(tmp_path / "good.csv"), _curve(tmp_path / "hours.csv", 3600.0)
    minutes = _curve(tmp_path / "minutes.csv", 60.0)
    for pair, blamed in (((good, hours), "hours.csv: t_s ends at 4"), ((hours, good), "hours.csv: t_s ends at 4"),
                         ((good, minutes), "minutes.csv: t_s spans 240 s, 60 times less than"),
                         ((minutes, good), "minutes.csv: t_s spans 240 s, 60 times less than")):
        assert main(["compare", *map(str, pair)]) == EXIT_USAGE
        err = capsys.readouterr().err
        assert blamed in err and "good.csv:" not in err


def test_design_refuses_a_target_in_hours_before_it_starts_naming_the_file(tmp_path, capsys):
    import json

    from labapp.errors import EXIT_USAGE
    from labapp.records.simcal import FORMAT, FORWARD_MODEL

    simcal = tmp_path / "simcal.json"
    simcal.write_text(json.dumps({"format": FORMAT, "forward_model": FORWARD_MODEL, "model": "constant",
                                  "physics": {"anisotropy": 1.0, "offset_mm": 0.0}, "seconds_per_mm": 1500.0,
                                  "g_per_mm3": 2e-3, "resolution": 16, "voxel_size_mm": 1.0, "water_g": 500.0}))
    out = tmp_path / "design"
    hours = _curve(tmp_path / "hours.csv", 3600.0)
    assert main(["design", "--target", str(hours), "--simcal", str(simcal), "--space", "extruded", "--resolution",
                 "16", "--max-iter", "20", "--out", str(out)]) == EXIT_USAGE
    assert f"{hours}: t_s ends at 4, a release over 4 s" in capsys.readouterr().err
    assert not out.exists()


def test_design_refuses_a_target_too_fast_to_have_a_rate_before_optimising(tmp_path, capsys):
    from labapp.errors import EXIT_USAGE

    step = tmp_path / "step.csv"                    # all of it released within 0.001 mm of tau
    step.write_text("tau_mm,released_mm3\n0,0\n1,0\n1.001,50\n3,50\n")
    out = tmp_path / "design"
    assert main(["design", "--target", str(step), "--space", "extruded", "--resolution", "16", "--max-iter", "10",
                 "--out", str(out)]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert f"target {step}: the middle 80% of its release" in err and "it   " not in err   # no evaluation ran
    assert not out.exists()
