"""Run folders are records: resume refuses anything but an interrupted run without writing a byte;
`sfr verify` fails with one line on every kind of damage and verifies other folders as what they are;
`sfr design --resume` keeps the target the run started with; a rejected design start blocks nothing."""
import hashlib
import json
import shutil
from pathlib import Path

import pytest

from labapp.cli.main import main
from labapp.errors import UsageError
from labapp.jobs.run import resumable
from labapp.records.runrecord import RecordKind, RecordStatus
from labapp.records.storage import create_run
from labapp.records.verification import verify_run

FIXTURES = Path(__file__).resolve().parents[3] / "fixtures" / "bench"
DEAD_PID = 2 ** 22 + 12345          # above the default pid_max: no live process has it


def tree(path: Path) -> dict[str, str]:
    """Every file under ``path`` (hidden ones too) with its SHA-256 and modification time."""
    return {str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest() + str(p.stat().st_mtime_ns)
            for p in sorted(path.rglob("*")) if p.is_file()}


def _run(tmp_path, kind=RecordKind.RUN, finish=None, frames=3) -> Path:
    run = create_run(tmp_path / "data", "r", {"kind": kind, "simulated": True,
                                             "config": {"name": "r", "interval_s": 11.0}})
    for k in range(frames):
        run.add_frame(f"frame_{k:06d}.jpg", bytes([k]) * 50, t_s=11.0 * k, t_unix_s=1e9 + 11 * k)
    if finish:
        run.finish(finish)
    else:
        run.update(writer_pid=DEAD_PID)          # the writer died: an interrupted run
    run.close()
    return run.path


@pytest.mark.parametrize("finish", [RecordStatus.COMPLETE, RecordStatus.STOPPED, RecordStatus.ABORTED, RecordStatus.FAILED])
def test_resume_refuses_a_finished_run_without_writing(tmp_path, capsys, finish):
    folder = _run(tmp_path, finish=finish)
    before = tree(folder)
    assert main(["run", "--resume", str(folder), "--out", str(tmp_path / "data")]) == 2
    err = capsys.readouterr().err
    assert f"finished ({finish})" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert tree(folder) == before


def test_resume_refuses_other_kinds_of_folder_untouched(tmp_path, capsys):
    series = _run(tmp_path, kind=RecordKind.CALIBRATION_SERIES)
    design = tmp_path / "design"
    design.mkdir()
    (design / "config.json").write_text("{}")
    (design / "feasibility.txt").write_text("ok")
    for folder, says in ((series, "calibration-series"), (design, "not a run folder (design)"),
                         (tmp_path / "missing", "does not exist"), (FIXTURES / "run", "not a run folder")):
        before = tree(folder) if folder.exists() else {}
        assert main(["run", "--resume", str(folder)]) == 2
        assert says in capsys.readouterr().err
        assert (tree(folder) if folder.exists() else {}) == before


def test_only_an_interrupted_run_is_resumable(tmp_path):
    folder = _run(tmp_path)
    assert resumable(folder).status == RecordStatus.INTERRUPTED
    live = create_run(tmp_path / "data", "live", {"kind": "run", "config": {}})
    with pytest.raises(UsageError, match="being written by process"):
        resumable(live.path)
    live.close()


def _verify(folder, capsys) -> tuple[int, str]:
    code = main(["verify", str(folder)])
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    return code, out.out.strip().splitlines()[-1]


def test_verify_passes_a_good_record(tmp_path, capsys):
    assert _verify(_run(tmp_path, finish=RecordStatus.COMPLETE), capsys) == (0, "OK")


@pytest.mark.parametrize("damage, reason", [
    (lambda f: (f / "frames.csv").unlink(), "manifest frames.csv is missing"),
    (lambda f: (f / "events.log").unlink(), "event log events.log is missing"),
    (lambda f: (f / "run.json").write_text('{"kind": "run", "stat'), "run.json is torn"),
    (lambda f: _tear_middle_row(f / "frames.csv"), "frames.csv line 3: damaged row"),
    (lambda f: _tear_middle_row(f / "events.log", b"\t"), "events.log line 2 is damaged"),
    (lambda f: (f / "frame_000001.jpg").unlink(), "listed file(s) absent: frame_000001.jpg"),
    (lambda f: (f / "extra.jpg").write_bytes(b"x"), "present but not listed: extra.jpg"),
    (lambda f: (f / "frame_000002.jpg").write_bytes(b"y"), "altered (SHA-256 differs): frame_000002.jpg"),
    (lambda f: _set_kind(f, "design"), "run.json names kind 'design'"),
    (lambda f: _set_kind(f, "calibration-series"), "masses.csv is missing"),
])
def test_verify_fails_with_one_line_reason(tmp_path, capsys, damage, reason):
    folder = _run(tmp_path, finish=RecordStatus.COMPLETE)
    damage(folder)
    code, last = _verify(folder, capsys)
    assert code == 1 and last.startswith("FAILED: ") and reason in last


def _tear_middle_row(path: Path, sep=b",") -> None:
    lines = path.read_bytes().split(b"\n")
    lines[2 if path.name == "frames.csv" else 1] = sep.join(lines[2 if path.name == "frames.csv" else 1].split(sep)[:2])
    path.write_bytes(b"\n".join(lines))


def _set_kind(folder: Path, kind: str) -> None:
    meta = json.loads((folder / "run.json").read_text())
    (folder / "run.json").write_text(json.dumps(dict(meta, kind=kind)))


def test_verify_checks_fixture_and_image_folders_as_what_they_are(tmp_path, capsys):
    code, last = _verify(FIXTURES / "run", capsys)
    assert code == 0 and last == "OK"
    code, last = _verify(FIXTURES / "calibration", capsys)
    assert code == 0 and last == "OK"
    images = tmp_path / "card"
    images.mkdir()
    for name in ("a.jpg", "b.jpg"):
        shutil.copyfile(FIXTURES / "run" / "frame_0000.jpg", images / name)
    report = verify_run(images)
    assert report.ok and report.kind == "plain image folder (no manifest)" and report.n_frames == 2
    copy = tmp_path / "fixture"
    shutil.copytree(FIXTURES / "run", copy)
    (copy / "frame_0003.jpg").unlink()
    shutil.copyfile(FIXTURES / "run" / "frame_0000.jpg", copy / "stray.jpg")
    report = verify_run(copy)
    assert not report.ok and report.missing == ["frame_0003.jpg"] and report.unlisted == ["stray.jpg"]
    code, last = _verify(tmp_path / "nothing-here", capsys)
    assert code == 1 and "does not exist" in last


TINY = ["--space", "extruded", "--resolution", "16", "--radius", "2"]


def test_design_resume_uses_the_target_it_started_with(tmp_path, capsys):
    target = tmp_path / "target.csv"
    target.write_text("tau_mm,released_mm3\n0,0\n1,40\n2,70\n3,90\n4,100\n")
    out = tmp_path / "d"
    # 3 evaluations leave no solid yet: a failed job (exit 1) whose run resumes all the same
    assert main(["design", "--target", str(target), *TINY, "--max-iter", "3", "--out", str(out)]) == 1
    record = json.loads((out / "target_source.json").read_text())
    assert record["sha256"] == hashlib.sha256(target.read_bytes()).hexdigest()
    assert (out / record["copy"]).read_bytes() == target.read_bytes()
    assert json.loads((out / "config.json").read_text())["target"] == str((out / record["copy"]).resolve())
    target.write_text("tau_mm,released_mm3\n0,0\n1,1\n")         # the original changes
    capsys.readouterr()
    assert main(["design", "--resume", "--max-iter", "4", "--out", str(out)]) == 1
    assert "has changed" in capsys.readouterr().err
    (out / record["copy"]).write_text("tau_mm,released_mm3\n0,0\n1,2\n")   # the run's own copy altered
    assert main(["design", "--resume", "--out", str(out)]) == 2


def test_a_rejected_design_start_leaves_nothing_behind(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("tau_mm,released_mm3\n0,0\n1,nan\n")
    out = tmp_path / "d"
    assert main(["design", "--target", str(bad), *TINY, "--max-iter", "2", "--out", str(out)]) == 2
    assert "row 3, released_mm3" in capsys.readouterr().err
    assert not out.exists()
    out.mkdir()                                                   # an empty folder given by the operator stays
    long = tmp_path / "long.csv"                                  # rejected after config.json was written
    long.write_text("tau_mm,released_mm3\n0,0\n10,50\n50,100\n")
    assert main(["design", "--target", str(long), *TINY, "--max-iter", "2", "--domain-mm", "10", "10", "10",
                 "--out", str(out)]) == 2
    assert f"{long}: the curve rises until tau = 50 mm" in capsys.readouterr().err
    assert out.is_dir() and not any(out.iterdir())
    assert main(["design", "--target", "sphere", *TINY, "--max-iter", "2", "--out", str(out)]) == 1  # no solid yet


def test_a_frame_written_but_not_recorded_before_a_crash_is_kept_aside_on_reopen(tmp_path):
    # the crash window between a frame's atomic rename and its frames.csv row leaves one unlisted frame
    from labapp.records.manifests import UNRECORDED_DIR
    from labapp.records.storage import open_run
    folder = _run(tmp_path, frames=3)
    (folder / "frame_000003.jpg").write_bytes(b"x" * 50)
    report = verify_run(folder)
    assert not report.ok and report.unlisted == ["frame_000003.jpg"]
    assert any("never recorded" in n for n in report.notes)
    run = open_run(folder)
    run.add_frame("frame_000003.jpg", b"y" * 50, t_s=33.0, t_unix_s=1e9 + 33)   # the name is free again
    run.finish(RecordStatus.STOPPED)
    run.close()
    assert (folder / UNRECORDED_DIR / "frame_000003.jpg").read_bytes() == b"x" * 50   # nothing lost
    assert "kept aside" in (folder / "events.log").read_text()
    assert verify_run(folder).ok
