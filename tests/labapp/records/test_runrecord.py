"""run.json is read through one typed loader: every layout reads (layout 0 has no ``format``), nothing is
rewritten on read, a resumed record keeps its layout, a newer format is refused by name."""
import json
import shutil
from pathlib import Path

import pytest

from labapp.jobs.run import resumable
from labapp.records.fileio import StorageError
from labapp.records.manifests import read_record, read_run
from labapp.records.outpaths import folder_kind
from labapp.records.runrecord import FORMAT, RecordFormatError, RecordKind, RecordStatus, RunRecord, migrate
from labapp.records.storage import create_run, open_run
from labapp.records.verification import verify_run

FIXTURES = Path(__file__).resolve().parents[3] / "fixtures" / "bench"
DEAD_PID = 2 ** 22 + 12345          # above the default pid_max: no live process has it

LAYOUT_0 = {                        # a run.json as written before records carried their format
    "kind": "run", "name": "r", "status": "running", "config": {"name": "r", "interval_s": 11.0},
    "created_unix_s": 1.0e9, "gaps": [], "simulated": True, "water_g": 500.0, "object_mass_g": 1.75,
    "writer_pid": DEAD_PID, "writer_started": 1.0e9,
}


def _layout_0_run(tmp_path: Path) -> Path:
    """An interrupted run folder whose run.json has no ``format`` (frames listed with their SHA-256)."""
    run = create_run(tmp_path / "data", "r", {})
    for k in range(2):
        run.add_frame(f"frame_{k:06d}.jpg", bytes([k]) * 50, t_s=11.0 * k, t_unix_s=1e9 + 11 * k)
    run.close()
    (run.path / "run.json").write_text(json.dumps(LAYOUT_0, indent=2, sort_keys=True))
    return run.path


def test_a_run_json_without_format_reads_as_the_current_layout_and_is_not_rewritten(tmp_path):
    folder = _layout_0_run(tmp_path)
    before = (folder / "run.json").read_bytes()
    record = read_record(folder)
    assert record.format == FORMAT and record.kind is RecordKind.RUN and record.status is RecordStatus.RUNNING
    assert record.files == {} and record.gaps == () and record.resumed == 0 and record.simulated
    assert record.object_mass_g == 1.75 and record.stored == LAYOUT_0
    snap = read_run(folder)
    assert snap.status == RecordStatus.INTERRUPTED == "interrupted" and snap.meta == LAYOUT_0
    assert resumable(folder).record.config == LAYOUT_0["config"]
    assert verify_run(folder).ok and folder_kind(folder) == "run"
    assert (folder / "run.json").read_bytes() == before


def test_a_resumed_record_keeps_its_layout(tmp_path):
    folder = _layout_0_run(tmp_path)
    run = open_run(folder)
    run.finish(RecordStatus.STOPPED)
    run.close()
    stored = json.loads((folder / "run.json").read_text())
    assert "format" not in stored and stored["status"] == "stopped" and stored["resumed"] == 1
    assert set(stored) == set(LAYOUT_0) | {"resumed", "finished_unix_s", "seal"}  # sealed from now on
    assert verify_run(folder).ok


def test_new_records_carry_the_format_and_plain_json_values(tmp_path):
    run = create_run(tmp_path, "r", {"kind": RecordKind.CALIBRATION_SERIES})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    stored = json.loads((run.path / "run.json").read_text())
    assert stored["format"] == FORMAT == 1 and stored["status"] == "complete"
    assert stored["kind"] == "calibration-series" and type(stored["status"]) is str


def test_the_bench_fixtures_read_without_being_touched(tmp_path):
    for name, kind in (("run", RecordKind.RUN), ("calibration", RecordKind.CALIBRATION_SERIES)):
        folder = tmp_path / name
        shutil.copytree(FIXTURES / name, folder)
        before = (folder / "run.json").read_bytes()
        record = read_record(folder)
        assert record.kind == kind and record.status == RecordStatus.CREATED and record.format == FORMAT
        assert record.crop == {"x": 180, "y": 262, "size": 120} and record.grid == 10 and record.water_g == 500.0
        assert verify_run(folder).ok and verify_run(folder).status == "not recorded"
        assert (folder / "run.json").read_bytes() == before


def test_migrate_copies_and_fills_what_absence_means():
    stored = {"water_g": 500.0}
    migrated = migrate(stored)
    assert stored == {"water_g": 500.0}
    assert migrated == {"water_g": 500.0, "format": FORMAT, "kind": "run", "status": "created", "files": {},
                        "gaps": [], "resumed": 0, "simulated": False}
    assert migrate(migrated) == migrated


def test_unknown_values_are_kept_as_stored():
    record = RunRecord.from_stored({"kind": "design", "status": "paused"})
    assert record.kind == "design" and not isinstance(record.kind, RecordKind)
    assert record.status == "paused" and not isinstance(record.status, RecordStatus)


@pytest.mark.parametrize("stored, message", [
    ({"format": FORMAT + 1}, f"format {FORMAT + 1} is newer than this version of sfr reads"),
    ({"format": "1"}, "format '1' is not a layout number"),
    ({"gaps": [{"after_t_s": 1.0}]}, "gaps is not a list of"),
    ({"files": ["a.jpg"]}, "files is not an object"),
])
def test_a_record_this_version_cannot_read_is_refused_by_name(tmp_path, stored, message):
    with pytest.raises(RecordFormatError, match=message):
        RunRecord.from_stored(stored)
    (tmp_path / "run.json").write_text(json.dumps(stored))
    with pytest.raises(StorageError, match=f"run.json {message}"):
        read_record(tmp_path)
