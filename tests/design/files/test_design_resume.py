"""What a design resume guarantees: a finished run is left as it is, outputs cut short are written from the
finished state (at its final beta), settings cannot change, an ico run resumes exactly, bad checkpoints."""
import dataclasses
import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from design.errors import DesignError
from design.files.records import CHECKPOINT, load_checkpoint, save_checkpoint
from design.files.rundir import run_design
from design.inverse.config import DesignConfig
from design.inverse.defect import ROUND_BETA_FACTOR

SMALL = dict(target="sphere", space="nfc", resolution=16, radius_vox=2.0, checkpoint_every=3)


def _hashes(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """A finished nfc run with beta continuation (beta 3 -> 12 over 4 stages)."""
    out = tmp_path_factory.mktemp("finished") / "run"
    result = run_design(DesignConfig(max_iter=40, **SMALL), out)
    assert result.status == "max_iter" and result.iterations == 40
    return out


def test_resuming_a_finished_run_changes_nothing(finished, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(finished, copy)
    before = _hashes(copy)
    mtimes = {p.name: p.stat().st_mtime_ns for p in copy.iterdir()}
    result = run_design(None, copy, resume=True)
    assert result.unchanged and result.status == "max_iter" and result.iterations == 40
    assert _hashes(copy) == before
    assert {p.name: p.stat().st_mtime_ns for p in copy.iterdir()} == mtimes  # not even rewritten
    # the same configuration given again, or a higher limit on a converged run, is no reason to work
    assert run_design(DesignConfig(max_iter=40, **SMALL), copy, resume=True).unchanged


@pytest.mark.parametrize("lost", [("summary.json",), ("summary.json", "density.npz", "design.stl")])
def test_outputs_cut_short_are_written_from_the_finished_state_at_its_final_beta(finished, tmp_path, lost):
    copy = tmp_path / "copy"
    shutil.copytree(finished, copy)
    for name in lost:  # Ctrl-C while the outputs were written: summary.json, written last, is missing
        (copy / name).unlink()
    # the physical-correction rounds ran at twice the final beta 12 (design.inverse.defect.ROUND_BETA_FACTOR)
    assert load_checkpoint(copy / CHECKPOINT).beta == pytest.approx(ROUND_BETA_FACTOR["nfc"] * 12.0)
    result = run_design(None, copy, resume=True)
    assert not result.unchanged and result.status == "max_iter" and result.iterations == 40
    with np.load(finished / "density.npz") as a, np.load(copy / "density.npz") as b:
        np.testing.assert_array_equal(a["rho"], b["rho"])  # projected at the final state's beta, not the start's 3
        np.testing.assert_array_equal(a["solid"], b["solid"])
    original = json.loads((finished / "summary.json").read_text())
    rewritten = json.loads((copy / "summary.json").read_text())
    for key in ("rel_rmse_print", "rel_rmse_density", "rel_rmse_design_grid_binary", "pieces", "volume_mm3",
                "iterations", "status"):
        assert rewritten[key] == original[key], key
    assert original["pieces"] >= 1
    assert (copy / "design.stl").read_bytes() == (finished / "design.stl").read_bytes()


def test_a_stale_summary_of_an_earlier_session_does_not_count_as_the_outputs(finished, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(finished, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary.update(status="stopped", iterations=5)  # a stopped session's summary; its resume was cut short
    (copy / "summary.json").write_text(json.dumps(summary))
    result = run_design(None, copy, resume=True)
    assert not result.unchanged and json.loads((copy / "summary.json").read_text())["iterations"] == 40


def test_a_resume_refuses_other_settings_and_may_raise_the_evaluation_limit(finished, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(finished, copy)
    with pytest.raises(DesignError, match=r"resolution 32 \(stored 16\)"):
        run_design(DesignConfig(max_iter=40, **dict(SMALL, resolution=32)), copy, resume=True)
    with pytest.raises(DesignError, match="max_iter 6 \\(stored 40\\)"):
        run_design(DesignConfig(max_iter=6, **SMALL), copy, resume=True)
    result = run_design(DesignConfig(max_iter=43, **SMALL), copy, resume=True)
    assert not result.unchanged and result.iterations == 43
    assert json.loads((copy / "config.json").read_text())["max_iter"] == 43


def _ico(max_iter: int) -> DesignConfig:
    # at 32 the elasticity solves have several multigrid levels (at 16 the coarse solve is direct and exact,
    # so no warm start matters); without correction rounds, whose share of the limit moves with it
    return DesignConfig(target="sphere", space="ico", resolution=32, radius_vox=2.0, layers=4, w_fab=3000.0,
                        max_iter=max_iter, checkpoint_every=4, physical_correction="none")


@pytest.fixture(scope="module")
def ico_whole(tmp_path_factory) -> Path:
    """An uninterrupted ico run of 10 evaluations."""
    out = tmp_path_factory.mktemp("ico") / "whole"
    assert run_design(_ico(10), out).iterations == 10
    return out


def test_an_interrupted_ico_run_resumes_exactly(ico_whole, tmp_path):
    """The ICO term's warm starts (each layer's last solution) are part of the checkpoint: without them the
    resumed PCG solves start elsewhere and the run drifts from the uninterrupted one."""

    def interrupt(k, x, terms):
        if k == 5:
            raise KeyboardInterrupt

    first = run_design(_ico(10), tmp_path / "cut", on_iteration=interrupt)
    assert first.status == "interrupted" and first.iterations == 5
    run_design(None, tmp_path / "cut", resume=True)
    a = np.loadtxt(ico_whole / "history.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "cut" / "history.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(b[:, 1:5], a[:, 1:5], rtol=1e-9, atol=0)  # J, J_fit, J_binary, J_fab
    sa = json.loads((ico_whole / "summary.json").read_text())["ico"]
    sb = json.loads((tmp_path / "cut" / "summary.json").read_text())["ico"]
    assert sa["pcg_iterations_mean"] == sb["pcg_iterations_mean"]


def test_an_ico_run_cut_by_its_limit_continues_exactly_with_a_higher_one(ico_whole, tmp_path):
    run_design(_ico(6), tmp_path / "cut")
    raised = dataclasses.replace(_ico(6), max_iter=10)  # the stored run's settings with a higher limit, as a resume gives them
    assert run_design(raised, tmp_path / "cut", resume=True).iterations == 10
    a = np.loadtxt(ico_whole / "history.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "cut" / "history.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(b[:, 1:5], a[:, 1:5], rtol=1e-9, atol=0)


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 truncated", None])
def test_an_empty_or_truncated_checkpoint_is_one_clear_error(finished, tmp_path, content):
    copy = tmp_path / "copy"
    shutil.copytree(finished, copy)
    data = (copy / CHECKPOINT).read_bytes()
    (copy / CHECKPOINT).write_bytes(data[: len(data) // 2] if content is None else content)
    with pytest.raises(DesignError, match=r"checkpoint\.npz: not a readable design checkpoint"):
        run_design(None, copy, resume=True)


def test_a_checkpoint_of_another_grid_is_refused(finished, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(finished, copy)
    saved = load_checkpoint(copy / CHECKPOINT)
    (copy / "summary.json").unlink()
    save_checkpoint(copy / CHECKPOINT, dataclasses.replace(saved, x=saved.x[:10], best_x=saved.best_x[:10]))
    with pytest.raises(DesignError, match=r"checkpoint\.npz: holds 10 design variables"):
        run_design(None, copy, resume=True)


def test_a_checkpoint_that_cannot_be_written_leaves_no_temporary_file(finished, tmp_path, monkeypatch):
    saved = load_checkpoint(finished / CHECKPOINT)
    path = tmp_path / CHECKPOINT

    monkeypatch.setattr("design.files.records.os", _FullDisk())  # the checkpoint's own writes only
    with pytest.raises(DesignError, match=r"cannot write the checkpoint .*checkpoint\.npz: No space left on device"):
        save_checkpoint(path, saved)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    save_checkpoint(path, saved)
    again = load_checkpoint(path)
    assert again.status == "max_iter" and again.beta == saved.beta and len(again.history) == 40
    assert [p.name for p in tmp_path.iterdir()] == [CHECKPOINT]


class _FullDisk:
    """``os`` for the checkpoint writer of a full disk: flushing to the disk fails."""

    def __getattr__(self, name):
        return getattr(os, name)

    @staticmethod
    def fsync(fd):
        raise OSError(28, "No space left on device")
