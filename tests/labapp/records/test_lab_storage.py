"""Run folders: atomic frames, manifests with SHA-256, torn rows, verify, sanitising, disk space."""
import csv
import json
import os

import psutil
import pytest

from labapp.records.fileio import StorageError, check_disk_space, sanitize_name
from labapp.records.manifests import read_run
from labapp.records.runrecord import RecordStatus
from labapp.records.storage import create_run, open_run
from labapp.records.verification import verify_run


def _run_with_frames(tmp_path, n=3):
    run = create_run(tmp_path, "pill test", {"water_g": 500.0})
    for k in range(n):
        run.add_frame(f"frame_{k:06d}.jpg", bytes([k]) * 100, t_s=11.0 * k, t_unix_s=1e9 + 11 * k,
                      plate_c=70.1, probe_c=None, speed_rpm=150.0)
    return run


def test_frames_are_listed_with_their_hash_and_verify(tmp_path):
    run = _run_with_frames(tmp_path)
    run.add_file("reference.jpg", b"clear water")
    run.finish(RecordStatus.COMPLETE)
    run.close()
    with open(run.path / "frames.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["file"] for r in rows] == ["frame_000000.jpg", "frame_000001.jpg", "frame_000002.jpg"]
    assert rows[1]["t_s"] == "11.000" and rows[1]["probe_c"] == "" and rows[1]["plate_c"] == "70.10"
    report = verify_run(run.path)
    assert report.ok and report.n_frames == 3 and report.status == RecordStatus.COMPLETE
    assert not list(run.path.glob(".*.part"))


def test_verify_reports_missing_altered_and_unlisted_files(tmp_path):
    run = _run_with_frames(tmp_path)
    run.close()
    (run.path / "frame_000001.jpg").write_bytes(b"tampered")
    (run.path / "frame_000002.jpg").unlink()
    (run.path / "stray.jpg").write_bytes(b"?")
    report = verify_run(run.path)
    assert not report.ok
    assert report.mismatched == ["frame_000001.jpg"] and report.missing == ["frame_000002.jpg"]
    assert report.unlisted == ["stray.jpg"]
    assert "FAILED" in report.lines()[-1]


def _orphan(run):
    """Make the run look like its writer process died (a crash)."""
    meta = json.loads((run.path / "run.json").read_text())
    meta["writer_started"] = 0.0
    (run.path / "run.json").write_text(json.dumps(meta))


def test_torn_last_row_is_reported_then_dropped_on_reopen(tmp_path):
    run = _run_with_frames(tmp_path, 2)
    run.close()
    _orphan(run)
    with open(run.path / "frames.csv", "a") as fh:
        fh.write("frame_000002.jpg,22.0,10000")          # a crash in the middle of a row
    snap = read_run(run.path)
    assert len(snap.frames) == 2 and snap.torn_bytes > 0 and snap.status == RecordStatus.INTERRUPTED
    assert not verify_run(run.path).ok
    reopened = open_run(run.path)
    assert reopened.status == RecordStatus.RUNNING and reopened.meta["resumed"] == 1
    reopened.add_frame("frame_000002.jpg", b"new", 22.0, 1e9 + 22)
    reopened.add_gap(11.0, 22.0, "test")
    reopened.finish(RecordStatus.STOPPED)
    reopened.close()
    report = verify_run(run.path)
    assert report.ok and report.n_frames == 3 and report.gaps[0].after_t_s == 11.0
    assert "interrupted" in (run.path / "events.log").read_text()


def test_a_frame_is_never_overwritten_and_folders_never_reused(tmp_path):
    run = _run_with_frames(tmp_path, 1)
    with pytest.raises(StorageError, match="never overwrites"):
        run.add_frame("frame_000000.jpg", b"again", 0.0, 0.0)
    other = create_run(tmp_path, "pill test", {})
    assert other.path != run.path and other.path.parent == tmp_path


def test_a_live_run_cannot_be_reopened_by_another_process(tmp_path):
    run = _run_with_frames(tmp_path, 1)
    meta = json.loads((run.path / "run.json").read_text())
    assert meta["writer_pid"] == os.getpid() and read_run(run.path).live
    meta["writer_pid"] = os.getppid()
    meta["writer_started"] = psutil.Process(os.getppid()).create_time()
    (run.path / "run.json").write_text(json.dumps(meta))
    with pytest.raises(StorageError, match="being written by process"):
        open_run(run.path)


@pytest.mark.parametrize("text, expected", [("pill v2 (70C)", "pill_v2_70C"), ("../../etc/passwd", "etc_passwd"),
                                            (".hidden", "hidden"), ("a/b\\c", "a_b_c")])
def test_names_from_user_text_are_sanitised(text, expected):
    assert sanitize_name(text) == expected


def test_unusable_names_and_paths_outside_are_refused(tmp_path):
    with pytest.raises(StorageError, match="no usable characters"):
        sanitize_name("../..")
    run = create_run(tmp_path / "data", "../escape", {})
    assert run.path.parent == tmp_path / "data"
    assert run.path.name.endswith("_escape")


def test_disk_space_check_refuses_a_run_that_cannot_fit(tmp_path):
    assert check_disk_space(tmp_path, 1000, 10) > 0
    with pytest.raises(StorageError, match="not enough disk space"):
        check_disk_space(tmp_path, 10**15, 10**3)


def test_reading_a_non_run_folder_is_a_clear_error(tmp_path):
    with pytest.raises(StorageError, match="not a readable run folder"):
        read_run(tmp_path)


@pytest.mark.parametrize("field, value", [("water_g", 450.0), ("object_mass_g", 2.0), ("crop", {"x": 1, "y": 2, "size": 9})])
def test_verify_names_a_metadata_field_edited_after_the_run(tmp_path, field, value):
    run = _run_with_frames(tmp_path)
    run.update(object_mass_g=1.75, crop={"x": 0, "y": 0, "size": 10})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    assert verify_run(run.path).ok
    meta = json.loads((run.path / "run.json").read_text())
    meta[field] = value
    (run.path / "run.json").write_text(json.dumps(meta, indent=2))
    report = verify_run(run.path)
    assert not report.ok and f"run.json field '{field}' was changed after it was recorded" in report.reason


@pytest.mark.parametrize("column, new", [(1, "12.000"), (3, "65.00")])
def test_verify_names_a_frame_row_edited_after_the_run(tmp_path, column, new):
    run = _run_with_frames(tmp_path)
    run.finish(RecordStatus.COMPLETE)
    run.close()
    path = run.path / "frames.csv"
    lines = path.read_text().splitlines()
    cells = lines[2].split(",")
    cells[column] = new                          # frame_000001's time or plate temperature
    lines[2] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    report = verify_run(run.path)
    assert not report.ok and "frames.csv line 3, row 3 (frame_000001.jpg), was changed" in report.reason


def test_verify_names_added_fields_lost_rows_and_changed_masses(tmp_path):
    run = create_run(tmp_path, "series", {"kind": "calibration-series", "water_g": 500.0})
    for k in range(3):
        run.add_frame(f"frame_{k:06d}.jpg", bytes([k]) * 100, t_s=11.0 * k, t_unix_s=1e9 + 11 * k)
    (run.path / "masses.csv").write_text("file,added_mass_g\nframe_000000.jpg,0.000000\n")
    run.update()
    run.finish(RecordStatus.COMPLETE)
    run.close()
    assert verify_run(run.path).ok
    (run.path / "masses.csv").write_text("file,added_mass_g\nframe_000000.jpg,0.001000\n")
    assert "masses.csv was changed" in verify_run(run.path).reason
    meta = json.loads((run.path / "run.json").read_text())
    meta["note"] = "added by hand"
    (run.path / "run.json").write_text(json.dumps(meta))
    assert "run.json field 'note' was added after the run was recorded" in verify_run(run.path).reason
    del meta["note"]
    (run.path / "run.json").write_text(json.dumps(meta))
    (run.path / "masses.csv").write_text("file,added_mass_g\nframe_000000.jpg,0.000000\n")
    path = run.path / "frames.csv"
    path.write_text("".join(path.read_text().splitlines(keepends=True)[:-1]))
    assert "frames.csv lost 1 recorded row(s)" in " ".join(verify_run(run.path).problems)
