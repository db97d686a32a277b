"""The records of a design run folder: format written on save, format-less (layout 0) records read and
resumed as before, newer formats refused."""
import json

import numpy as np
import pytest

from design.errors import DesignError
from design.files.records import (
    CHECKPOINT_FORMAT,
    CONFIG_FORMAT,
    SUMMARY_FORMAT,
    load_checkpoint,
    load_config,
    load_summary,
    migrate_config,
    migrate_summary,
    save_checkpoint,
)
from design.files.rundir import run_design
from design.inverse.config import DesignConfig
from design.inverse.optimize import HISTORY_COLUMNS, Checkpoint
from design.inverse.status import DesignStatus

SMALL = dict(target="sphere", space="nfc", resolution=16, radius_vox=2.0, checkpoint_every=3)


def _history(folder):
    return np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1)[:, :-1]  # all but seconds


def test_every_record_of_a_run_carries_its_format(tmp_path):
    run_design(DesignConfig(max_iter=4, **SMALL), tmp_path)
    assert json.loads((tmp_path / "config.json").read_text())["format"] == CONFIG_FORMAT == 2
    assert json.loads((tmp_path / "summary.json").read_text())["format"] == SUMMARY_FORMAT == 2
    with np.load(tmp_path / "checkpoint.npz") as saved:
        assert int(saved["format"]) == CHECKPOINT_FORMAT == 2
    assert load_config(tmp_path) == DesignConfig(max_iter=4, **SMALL)
    summary = load_summary(tmp_path)
    assert summary["status"] is DesignStatus.MAX_ITER and summary["iterations"] == 4


def test_a_format_less_config_reads_its_missing_options_as_the_run_had_them():
    stored = {"target": "sphere", "space": "nfc", "beta": 3.0, "beta_final": None}
    record = migrate_config(stored)
    assert record["format"] == 2 and record["beta_final"] == 3.0  # None always meant a fixed beta
    assert (record["rate_span"], record["optimizer"], record["allow_pieces"], record["connect_planes"],
            record["connect_tail"], record["line_search"]) == ((0.0, 1.0), "LD_LBFGS", True, False, 0.0, "strong-wolfe")
    current = migrate_config({"format": 1, "target": "sphere", "beta": 3.0, "beta_final": None})
    assert current["beta_final"] == 3.0 and "optimizer" not in current  # layout 1 stores every option
    assert current["physical_correction"] == "none" == record["physical_correction"]  # but the correction came later
    assert stored == {"target": "sphere", "space": "nfc", "beta": 3.0, "beta_final": None}  # not changed


def test_a_format_less_summary_reads_the_facts_recorded_since_as_not_recorded():
    old = {"status": "max_iter", "rel_rmse_binary": 0.02, "rate_dev_mid80": {"density": 0.01, "binary": 0.03}}
    summary = migrate_summary(old)
    assert summary["format"] == 2 and summary["status"] is DesignStatus.MAX_ITER
    assert summary["enclosed_voids"] is None and summary["ico"] is None
    assert summary["rate_dev_mid80"] == {"print": None, "density": 0.01, "design_grid_binary": 0.03}
    assert migrate_summary({"format": 1, "status": "someday"})["status"] == "someday"  # kept as stored


def test_a_layout_1_summary_reads_its_binary_fit_as_the_design_grid_s_and_has_no_print_fit():
    old = {"format": 1, "status": "converged", "rel_rmse_binary": 0.02, "rel_rmse_fine": 0.03, "fine_factor": 2,
           "rate_dev_mid80": {"density": 0.01, "binary": 0.03, "fine": 0.04}, "volume_mm3": 100.0}
    summary = migrate_summary(old)
    assert summary["format"] == 2 and summary["rel_rmse_design_grid_binary"] == 0.02
    assert summary["rel_rmse_print"] is None and summary["rel_rmse_print_error"] is None and summary["reference"] is None
    assert "rel_rmse_binary" not in summary and "rel_rmse_fine" not in summary and "fine_factor" not in summary
    assert summary["rate_dev_mid80"] == {"print": None, "density": 0.01, "design_grid_binary": 0.03}
    assert summary["volume_mm3"] == 100.0 and old["rel_rmse_binary"] == 0.02  # the stored record is not changed


@pytest.mark.parametrize("migrate", [migrate_config, migrate_summary])
def test_a_newer_or_malformed_format_is_refused(migrate):
    with pytest.raises(DesignError, match="format 3 is newer than this version reads"):
        migrate({"format": 3})
    with pytest.raises(DesignError, match="format '1' is not a layout number"):
        migrate({"format": "1"})


def test_a_format_less_checkpoint_of_the_oldest_layout_reads_with_its_gaps_filled(tmp_path):
    history = np.array([[1, 5.0, 4.0, 1.0, 0.0, 0.3, 2.0], [2, 3.0, 2.5, 0.5, 0.0, 0.2, 4.0]])  # no fab_seconds
    np.savez(tmp_path / "checkpoint.npz", x=np.zeros(8), best_x=np.ones(8), history=history)
    ckpt = load_checkpoint(tmp_path / "checkpoint.npz")
    assert ckpt.history.shape == (2, len(HISTORY_COLUMNS)) and list(ckpt.history[:, 5]) == [0.0, 0.0]
    assert list(ckpt.history[:, 6]) == [0.3, 0.2] and ckpt.best_value == 3.0 and ckpt.stage == 0
    assert ckpt.lbfgs == {} and ckpt.fab == {} and np.isnan(ckpt.beta) and ckpt.status is None  # not recorded
    newer = Checkpoint(np.zeros(2), np.zeros(2), 1.0, 0, np.zeros((1, len(HISTORY_COLUMNS))))
    save_checkpoint(tmp_path / "new.npz", newer)
    with np.load(tmp_path / "new.npz") as saved:
        arrays = dict(saved)
    np.savez(tmp_path / "new.npz", **dict(arrays, format=3))
    with pytest.raises(DesignError, match="format 3 is newer"):
        load_checkpoint(tmp_path / "new.npz")


def test_a_run_folder_without_formats_resumes_exactly_as_the_uninterrupted_run(tmp_path):
    config = DesignConfig(max_iter=12, **SMALL)
    run_design(config, tmp_path / "whole")
    calls = []
    run_design(config, tmp_path / "parts", should_stop=lambda: len(calls) >= 5,
               on_iteration=lambda k, x, terms: calls.append(k))
    folder = tmp_path / "parts"
    stored = json.loads((folder / "config.json").read_text())
    del stored["format"]
    (folder / "config.json").write_text(json.dumps(stored, indent=2))
    with np.load(folder / "checkpoint.npz") as saved:
        arrays = {name: saved[name] for name in saved.files if name != "format"}
    np.savez(folder / "checkpoint.npz", **arrays)
    summary = json.loads((folder / "summary.json").read_text())
    del summary["format"]
    (folder / "summary.json").write_text(json.dumps(summary))
    assert load_summary(folder)["status"] is DesignStatus.STOPPED
    resumed = run_design(None, folder, resume=True)
    assert resumed.iterations == 12
    assert load_summary(folder)["config"] == load_summary(tmp_path / "whole")["config"]
    np.testing.assert_array_equal(_history(folder), _history(tmp_path / "whole"))
