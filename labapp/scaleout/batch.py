"""Batch reanalysis: many run folders through the analysis job at once, on Dask workers, with one table.

Each run is analysed by `labapp.jobs.analyse.analyse_run` (what `sfr analyze RUN` runs) into ``DIR/NAME/``;
``DIR/batch_summary.csv`` gets one row per run (`TABLE_COLUMNS`): final concentration and release,
MDT and DE (`labapp.jobs.compare.release_summary`), and f1/f2 against a reference curve when one is given
(`analysis.similarity`, percent of the reference's weighed mass or final release). A run that cannot
be analysed is a row with its error; the others go on.
"""
from __future__ import annotations

import csv
import enum
import json
import logging
import os
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from analysis import BenchCalibration, ReleaseProfile, similarity
from labapp.errors import UsageError
from labapp.jobs.analyse import analyse_run
from labapp.jobs.compare import profile_of
from labapp.records.curvefiles import read_physical_curve
from labapp.records.fileio import sanitize_name
from labapp.records.outpaths import FolderKind, check_out
from labapp.scaleout.sweep import Progress

log = logging.getLogger(__name__)

TABLE = "batch_summary.csv"
TABLE_COLUMNS = ("name", "run", "status", "error", "frames", "duration_s", "final_conc_g_per_kg", "final_released_g",
                 "mdt_s", "de_pct", "f1", "f2", "f2_points", "f2_note", "best_fit", "folder")
TASK_MEMORY_GB = 1.0
"""Peak memory of one run's analysis (decoded frames are reduced to per-cell values as they come), GB."""


class RowStatus(enum.StrEnum):
    """``status`` of a run's row in ``batch_summary.csv``."""

    DONE = "done"
    FAILED = "failed"
    NOT_ANALYSED = "not analysed"
    """No result yet: the batch is running, or was stopped before the run's turn."""


@dataclass(frozen=True)
class BatchResult:
    """Rows in the order the runs were given, the table written, and whether Ctrl-C cut the batch short."""

    rows: list[dict]
    table: Path
    stopped: bool


def output_names(runs: list[str | Path]) -> list[str]:
    """One distinct folder name per run: its own name, with its parent's when two runs share a name."""
    base = [sanitize_name(Path(r).resolve().name) for r in runs]
    names = [b if base.count(b) == 1 else sanitize_name(f"{Path(r).resolve().parent.name}_{b}")
             for r, b in zip(runs, base)]
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            names[i] = f"{name}-{seen[name]}"
    return names


def analyse_one(run: str, calibration: str, out: str, reference: ReleaseProfile | None = None,
                options: dict | None = None) -> dict:
    """Analyse one run into ``out`` and return its table row; never raises (a failure is a row).

    Parameters
    ----------
    run, calibration, out : str
        Run folder, bench calibration JSON, output folder.
    reference : ReleaseProfile, optional
        For f1/f2 (s, g).
    options : dict, optional
        Keyword arguments of `labapp.jobs.analyse.analyse_run` (interval_s, water_g, window_s, order, workers,
        reduce, plot).
    """
    row = {"run": str(run), "folder": Path(out).name}
    try:
        result = analyse_run(run, calibration, out, **(options or {}))
        curve = result.curve
        summary = json.loads((result.out / "summary.json").read_text())
        release = summary.get("release", {})
        row.update(status=RowStatus.DONE, frames=len(curve.files), duration_s=summary["duration_s"],
                   final_conc_g_per_kg=float(curve.conc_smooth_g_per_kg[-1]),
                   final_released_g=summary["final_released_g"], mdt_s=release.get("mdt_s"),
                   de_pct=release.get("de_pct"), best_fit=release.get("best_fit_text"),
                   error=release.get("error"))
        if reference is not None:
            test = ReleaseProfile(curve.t_s, curve.released_g, "s", "g", curve.object_mass_g, str(run))
            sim = similarity(reference, test)
            row.update(f1=sim.f1, f2=sim.f2, f2_points=sim.points_used, f2_note=sim.reason)
    except Exception as exc:  # noqa: BLE001 -- one bad run is a row with its error; the batch goes on
        log.debug("analysis of %s failed:\n%s", run, traceback.format_exc())
        row.update(status=RowStatus.FAILED, error=f"{type(exc).__name__}: {exc}")
    return {k: ("" if v is None else v) for k, v in row.items()}


def check_runs(runs: list[str | Path]) -> None:
    """Refuse a batch naming run folders that do not exist, all of them named, before any work (or cluster).

    Raises
    ------
    labapp.errors.UsageError
    """
    missing = [str(r) for r in runs if not Path(r).is_dir()]
    if missing:
        raise UsageError(f"{len(missing)} of the {len(runs)} run folders do not exist or are not folders: "
                         f"{', '.join(missing)}; nothing was analysed")


def analyse_many(runs: list[str | Path], calibration: str | Path, out: str | Path, client=None, *,
                 reference: str | Path | None = None, on_progress: Callable[[Progress], None] | None = None,
                 **options) -> BatchResult:
    """Analyse every run (on `client`'s workers, or one after another here) and write the summary table.

    Parameters
    ----------
    runs : list of path
    calibration : path
        Bench calibration JSON, for every run.
    out : path
        The batch folder (new, empty, or an earlier batch folder whose analyses are replaced).
    client : distributed.Client, optional
    reference : path, optional
        A curve file or run folder (analysed with `calibration`) for f1/f2.
    on_progress : callable, optional
        Called with a `labapp.scaleout.sweep.Progress` as runs finish.
    **options
        Passed to `labapp.jobs.analyse.analyse_run`; ``workers`` (decoding threads per run) defaults to 1.

    Raises
    ------
    labapp.records.outpaths.OutPathError
        For an ``out`` that is or holds an input or another command's folder.
    labapp.records.curvefiles.CurveFileError
        For a reference that cannot be read.
    labapp.errors.UsageError
        For run folders that do not exist (all named; nothing is analysed).
    """
    if not runs:
        raise ValueError("give at least one run folder")
    out = check_out(out, FolderKind.BATCH_ANALYSIS, [calibration, reference, *runs], replace=True)   # a rerun completes it
    BenchCalibration.load(calibration)  # a bad calibration stops the batch before any work
    check_runs(runs)
    ref = None
    if reference is not None:
        ref = profile_of(read_physical_curve(reference, calibration=BenchCalibration.load(calibration)),
                         f"reference {reference}")
    options = {"workers": 1, **options}
    names = output_names(runs)
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(str(Path(r).resolve()), str(Path(calibration).resolve()), str(out / n)) for r, n in zip(runs, names)]
    _write_table(out, jobs, names, {})  # marks the folder as a batch at once, so an interrupted one reruns
    report, t0 = on_progress or (lambda p: None), time.perf_counter()
    rows: dict[int, dict] = {}

    def progress(running: int) -> None:
        left = len(jobs) - len(rows) - running
        eta = (left + running) * (time.perf_counter() - t0) / len(rows) if rows else None
        report(Progress(len(rows), sum(r["status"] == RowStatus.FAILED for r in rows.values()), running, left, eta))

    stopped = False
    try:
        if client is None:
            for i, job in enumerate(jobs):
                progress(1)
                rows[i] = analyse_one(*job, ref, options)
        else:
            from distributed import as_completed

            futures = {client.submit(analyse_one, *job, ref, options, pure=False): i for i, job in enumerate(jobs)}
            progress(min(len(jobs), len(client.scheduler_info()["workers"])))
            for fut in as_completed(futures):
                rows[futures[fut]] = fut.result()
                progress(min(len(jobs) - len(rows), len(client.scheduler_info()["workers"])))
    except KeyboardInterrupt:
        stopped = True
        if client is not None:
            client.cancel(list(futures))
    progress(0)
    table_rows = _write_table(out, jobs, names, rows)
    return BatchResult(table_rows, out / TABLE, stopped)


def _write_table(out: Path, jobs: list, names: list[str], rows: dict[int, dict]) -> list[dict]:
    """Write the summary table (atomically); runs without a result yet are "not analysed"."""
    table_rows = [{"name": name, **rows.get(i, {"run": job[0], "folder": name, "status": RowStatus.NOT_ANALYSED})}
                  for i, (job, name) in enumerate(zip(jobs, names))]
    tmp = out / f"{TABLE}.tmp"
    with open(tmp, "w", newline="") as fh:
        writer = csv.DictWriter(fh, TABLE_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(table_rows)
    os.replace(tmp, out / TABLE)
    return table_rows
