"""The sweep job: every combination of a sweep spec as one `sfr design` run folder, on Dask workers.

Layout of a sweep folder ``DIR``::

    DIR/spec.toml            the spec of the first run (a changed spec is kept beside it, timestamped)
    DIR/runs/NAME/           one ordinary design run folder per combination (`sfr design --resume` works)
    DIR/failed/NAME.txt      the error and traceback of a failed combination
    DIR/sweep.log            one line per start, finish and failure, with the worker that ran it
    DIR/sweep.csv            the table of every combination (`TABLE_COLUMNS`)
    DIR/contact_sheet.png    each design's fit and picture, best first (`labapp.figures.contact_sheet`)

A combination is done when its folder's ``summary.json`` has a final status (`design.inverse.status.FINISHED`); a rerun
skips those and resumes the others from their checkpoints. A worker holds an exclusive lock on the run
folder while it designs, so a task Dask reschedules after a worker died, while a stale copy is still
running somewhere, waits and then finds the design done or resumes it: each combination is designed
once. The same `run_combination` runs one after another in this process without a Dask client.

`sweep_on_cluster` is the job `sfr sweep` and the GUI's sweep panel call: it starts (or joins) the Dask
cluster and runs `run_sweep` on it.
"""
from __future__ import annotations

import csv
import enum
import fcntl
import json
import logging
import os
import socket
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from design.errors import DesignError
from design.files.records import load_summary
from design.inverse.status import FINISHED, DesignStatus
from labapp.errors import UsageError
from labapp.figures.contact_sheet import draw_contact_sheet, rank, summary_row
from labapp.jobs.design import design
from labapp.records.outpaths import FolderKind, check_out
from labapp.records.simcal import load_simcal
from labapp.scaleout.cluster import dashboard_link, dask_client, design_memory_gb
from labapp.scaleout.sweepspec import Combination, SweepSpec, config_matches

log = logging.getLogger(__name__)

RUNS, FAILED, LOCKS = "runs", "failed", ".locks"
STOP_POLL_S = 1.0
"""How often a running design asks the scheduler whether the sweep was stopped, s."""
TABLE_COLUMNS = ("name", "status", "error", "rel_rmse_print", "rel_rmse_print_error", "rel_rmse_density",
                 "rel_rmse_design_grid_binary", "rmse_mm3", "rel_rmse_physical", "rate_dev_print",
                 "rate_dev_design_grid_binary", "pieces", "overhang_fraction", "min_channel_mm", "enclosed_void_mm3",
                 "warn_channel_mm", "print_mass_g", "iterations", "seconds", "folder")
"""Columns of sweep.csv; the swept settings go between ``name`` and ``status``. ``rel_rmse_print`` (the
print's fit, design.stl by exact surface distances) is the headline; ``rmse_mm3`` is the print's too;
``rel_rmse_density`` and ``rel_rmse_design_grid_binary`` are the design grid's diagnostics."""


class SweepError(UsageError):
    """A sweep folder that cannot hold this sweep."""


class FolderState(enum.StrEnum):
    """Where a combination's run folder stands (`folder_state`)."""

    DONE = "done"
    """Its ``summary.json`` has a final status (`design.inverse.status.FINISHED`)."""
    RESUME = "resume"
    """Started (it has a ``config.json``): the design resumes from its checkpoint."""
    NEW = "new"


@dataclass(frozen=True)
class Progress:
    """Where a sweep stands: combinations done (failures included), running, left; ETA in s or None."""

    done: int
    failed: int
    running: int
    left: int
    eta_s: float | None
    dashboard: str | None = None


@dataclass
class SweepResult:
    """What `run_sweep` returns: the table rows (spec order), whether it was stopped, the files written."""

    rows: list[dict]
    stopped: bool
    table: Path
    contact_sheet: Path | None
    dashboard: str | None = None
    failed: list[str] = field(default_factory=list)


# ----------------------------------------------------------------------------------------------- worker side

def folder_state(folder: Path) -> FolderState:
    """Whether a combination's run folder is done, to be resumed or new."""
    try:
        status = load_summary(folder)["status"]
        if status in FINISHED:
            return FolderState.DONE
    except (OSError, ValueError, KeyError, DesignError):
        pass
    return FolderState.RESUME if (folder / "config.json").exists() else FolderState.NEW


def _log_line(sweep_dir: Path, text: str) -> None:
    line = f"{time.strftime('%Y-%m-%dT%H:%M:%S')} {text}\n".encode()
    fd = os.open(sweep_dir / "sweep.log", os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, line)  # one write of an O_APPEND file: lines from many workers do not interleave
    finally:
        os.close(fd)


def _stop_poller(event_name: str | None) -> Callable[[], bool] | None:
    """``should_stop`` for `run_design`: the sweep's Dask event, asked at most every `STOP_POLL_S`."""
    if event_name is None:
        return None
    from distributed import Event

    event, last = Event(event_name), [0.0, False]

    def should_stop() -> bool:
        now = time.monotonic()
        if now - last[0] >= STOP_POLL_S:
            last[0], last[1] = now, event.is_set()
        return last[1]
    return should_stop


def _design(combo: Combination, folder: Path, resume: bool, should_stop) -> str:
    """Start or resume the combination's design through the job `sfr design` runs; returns its status."""
    simcal = load_simcal(combo.simcal) if combo.simcal else None
    result, _ = design(None if resume else combo.config, folder, resume=resume, simcal=simcal,
                       should_stop=should_stop)
    return result.status


def run_combination(combo: Combination, sweep_dir: str, stop_event: str | None = None) -> dict:
    """Design one combination in ``sweep_dir/runs/NAME``, or find it done; never raises.

    Returns
    -------
    dict
        ``name``, ``status`` (a design status, or "failed"), ``error`` and ``traceback`` (failed only),
        ``seconds`` of this call, ``worker``.
    """
    sweep_dir = Path(sweep_dir)
    folder = sweep_dir / RUNS / combo.name
    where = _worker_name()
    t0 = time.perf_counter()
    (sweep_dir / LOCKS).mkdir(exist_ok=True)
    with open(sweep_dir / LOCKS / f"{combo.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released by the OS if this process dies
        state = folder_state(folder)
        if state == FolderState.DONE:
            status = load_summary(folder)["status"]
            return {"name": combo.name, "status": status, "seconds": 0.0, "worker": where, "skipped": True}
        if state == FolderState.NEW and folder.is_dir() and any(folder.iterdir()):
            _set_aside(folder, sweep_dir)
        _log_line(sweep_dir, f"start {combo.name} on {where} ({state})")
        try:
            status = _design(combo, folder, state == FolderState.RESUME, _stop_poller(stop_event))
        except Exception as exc:  # noqa: BLE001 -- a failed combination is recorded and the sweep goes on
            _log_line(sweep_dir, f"failed {combo.name} on {where}: {type(exc).__name__}: {exc}")
            return {"name": combo.name, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
                    "traceback": traceback.format_exc(), "seconds": time.perf_counter() - t0, "worker": where}
        seconds = time.perf_counter() - t0
        _log_line(sweep_dir, f"finish {combo.name} on {where}: {status} in {seconds:.2f} s")
        return {"name": combo.name, "status": status, "seconds": seconds, "worker": where}


def _set_aside(folder: Path, sweep_dir: Path) -> None:
    """Move what a start killed before its ``config.json`` left behind to ``failed/``, so it can restart."""
    aside = sweep_dir / FAILED / f"{folder.name}.aborted-{time.strftime('%Y%m%d-%H%M%S')}"
    aside.parent.mkdir(exist_ok=True)
    os.replace(folder, aside)
    _log_line(sweep_dir, f"moved the unfinished start of {folder.name} to {aside.relative_to(sweep_dir)}")


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"


# ----------------------------------------------------------------------------------------------- client side

@dataclass
class _Session:
    """This session's share of a sweep (``todo``; the rest of ``total`` was done before) and its outcomes."""

    total: int
    todo: list[Combination]
    dashboard: str | None = None
    outcomes: dict[str, dict] = field(default_factory=dict)
    t0: float = field(default_factory=time.perf_counter)

    def progress(self, running: int) -> Progress:
        """Counts over the whole sweep; the ETA is what remains (left and running) over this session's
        throughput so far."""
        done = len(self.outcomes)
        failed = sum(o["status"] == "failed" for o in self.outcomes.values())
        left = len(self.todo) - done - running
        eta = (left + running) * (time.perf_counter() - self.t0) / done if done else None
        return Progress(self.total - len(self.todo) + done, failed, running, left, eta, self.dashboard)


def prepare_sweep_dir(spec: SweepSpec, sweep_dir: str | Path) -> Path:
    """Check (before any work) that ``sweep_dir`` can hold this sweep, then store the spec in it.

    Raises
    ------
    labapp.records.outpaths.OutPathError
        The folder is a file, holds something other than a sweep, or holds an input.
    SweepError
        A combination's run folder holds a design with other settings.
    """
    sweep_dir = check_out(sweep_dir, FolderKind.SWEEP, [spec.target, spec.simcal], replace=True)   # a rerun resumes
    for combo in spec.combinations:
        stored = sweep_dir / RUNS / combo.name / "config.json"
        if stored.exists():
            try:
                same = config_matches(combo.config, json.loads(stored.read_text()))
            except (OSError, ValueError) as exc:
                raise SweepError(f"{stored} cannot be read ({exc}); move that run folder away") from exc
            if not same:
                raise SweepError(f"{stored.parent} holds a design with other settings than the spec's combination "
                                 f"{combo.name} (a top-level setting changed?); use a new --out")
    try:
        (sweep_dir / RUNS).mkdir(parents=True, exist_ok=True)
        first = sweep_dir / "spec.toml"
        if not first.exists():
            first.write_text(spec.text)
        elif first.read_text() != spec.text:
            (sweep_dir / f"spec-{time.strftime('%Y%m%d-%H%M%S')}.toml").write_text(spec.text)
    except OSError as exc:
        raise SweepError(f"cannot write to --out {sweep_dir}: {exc.strerror or exc}") from exc
    return sweep_dir


def run_sweep(spec: SweepSpec, sweep_dir: str | Path, client=None, *,
              on_progress: Callable[[Progress], None] | None = None,
              should_stop: Callable[[], bool] | None = None, contact_sheet: bool = True) -> SweepResult:
    """Run every unfinished combination of ``spec`` and write sweep.csv and the contact sheet.

    Parameters
    ----------
    spec : SweepSpec
    sweep_dir : str or Path
        The sweep folder (created; a rerun skips done combinations and resumes the others).
    client : distributed.Client or None
        Where the designs run; None runs them one after another in this process.
    on_progress : callable, optional
        Called with a `Progress` at start, after each combination and about once a second.
    should_stop : callable, optional
        Polled about once a second; True stops like Ctrl-C: running designs checkpoint and stop,
        queued ones do not start.

    Returns
    -------
    SweepResult
        ``stopped`` is True after Ctrl-C (KeyboardInterrupt) or `should_stop`.
    """
    sweep_dir = prepare_sweep_dir(spec, sweep_dir)
    todo = [c for c in spec.combinations if folder_state(sweep_dir / RUNS / c.name) != FolderState.DONE]
    log.info("sweep %s: %d combinations, %d to run", sweep_dir, len(spec.combinations), len(todo))
    session = _Session(len(spec.combinations), todo)
    report = on_progress or (lambda p: None)
    if client is None:
        stopped = _run_serial(session, sweep_dir, report, should_stop)
    else:
        session.dashboard = dashboard_link(client)
        stopped = _run_dask(client, session, sweep_dir, report, should_stop)
    report(session.progress(0))
    return _finish(spec, sweep_dir, session.outcomes, stopped, contact_sheet, session.dashboard)


@dataclass(frozen=True)
class ClusterStart:
    """What `sweep_on_cluster` reports once its cluster is up: the sweep folder, the workers, the memory one
    design takes (GB, which sized a local cluster) and the Dask dashboard (None without one)."""

    sweep_dir: Path
    workers: int
    task_memory_gb: float
    dashboard: str | None


def sweep_on_cluster(spec: SweepSpec, sweep_dir: str | Path, *, scheduler: str | None = None,
                     workers: int | None = None, on_start: Callable[[ClusterStart], None] | None = None,
                     on_progress: Callable[[Progress], None] | None = None,
                     should_stop: Callable[[], bool] | None = None) -> SweepResult:
    """The sweep job (`sfr sweep`, the GUI's sweep panel): check the sweep folder, start a local Dask cluster
    sized for the spec's largest design (or join ``scheduler``), and `run_sweep` on it.

    Parameters
    ----------
    spec : SweepSpec
    sweep_dir : str or Path
        The sweep folder, checked before the cluster starts.
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running scheduler; None starts a local cluster.
    workers : int, optional
        Local cluster: worker processes (default: as many as cores and memory allow); with ``scheduler``:
        wait for this many workers.
    on_start : callable, optional
        Called once with a `ClusterStart` when the cluster is up, before the first design.
    on_progress, should_stop : callable, optional
        As for `run_sweep`.

    Raises
    ------
    labapp.records.outpaths.OutPathError, SweepError
        As `prepare_sweep_dir`.
    labapp.scaleout.cluster.ClusterError
        The scheduler cannot be reached or the local cluster cannot start.
    """
    sweep_dir = prepare_sweep_dir(spec, sweep_dir)
    memory_gb = max(design_memory_gb(c.config.resolution, c.config.space) for c in spec.combinations)
    with dask_client(scheduler, workers=workers, task_memory_gb=memory_gb) as client:
        if on_start is not None:
            on_start(ClusterStart(sweep_dir, len(client.scheduler_info()["workers"]), memory_gb, dashboard_link(client)))
        return run_sweep(spec, sweep_dir, client, on_progress=on_progress, should_stop=should_stop)


def _run_serial(session: _Session, sweep_dir: Path, report, should_stop) -> bool:
    try:
        for combo in session.todo:
            if should_stop is not None and should_stop():
                return True
            report(session.progress(1))
            session.outcomes[combo.name] = run_combination(combo, str(sweep_dir))
            if session.outcomes[combo.name]["status"] == DesignStatus.INTERRUPTED:  # Ctrl-C, caught by the optimiser
                return True
    except KeyboardInterrupt:
        return True
    return False


def expected_work(combo: Combination) -> int:
    """A combination's expected cost, voxels x evaluations: Dask starts the costliest first, so that
    the sweep does not end with one long design running alone (longest-processing-time order)."""
    return combo.config.resolution ** 3 * combo.config.max_iter


def _run_dask(client, session: _Session, sweep_dir: Path, report, should_stop) -> bool:
    from distributed import Event, wait

    event_name = f"sfr-sweep-stop-{uuid.uuid4().hex}"
    stop_event = Event(event_name, client=client)
    order = sorted(session.todo, key=expected_work, reverse=True)
    futures = {client.submit(run_combination, c, str(sweep_dir), event_name, pure=False, priority=expected_work(c),
                             key=f"design-{c.name}-{uuid.uuid4().hex[:8]}"): c for c in order}
    pending = set(futures)
    try:
        while pending:
            report(session.progress(_running(client, pending)))
            try:
                finished = wait(list(pending), timeout=STOP_POLL_S, return_when="FIRST_COMPLETED").done
            except TimeoutError:
                finished = ()
            for fut in finished:
                pending.discard(fut)
                session.outcomes[futures[fut].name] = _outcome(fut, futures[fut])
            if should_stop is not None and should_stop():
                raise KeyboardInterrupt
    except KeyboardInterrupt:
        _stop(client, stop_event, pending, futures, session.outcomes)
        return True
    return False


def _stop(client, stop_event, pending: set, futures: dict, outcomes: dict) -> None:
    """Ctrl-C: queued designs never start, running ones checkpoint and stop; a second Ctrl-C leaves at once."""
    from distributed import wait

    log.warning("stopping: running designs checkpoint and stop (Ctrl-C again to leave at once)")
    stop_event.set()
    running = _running_keys(client)
    queued = [f for f in pending if str(f.key) not in running]
    client.cancel(queued)
    pending.difference_update(queued)
    try:
        wait(list(pending))
    except KeyboardInterrupt:
        client.cancel(list(pending))
        return
    for fut in pending:
        outcomes[futures[fut].name] = _outcome(fut, futures[fut])


def _outcome(fut, combo: Combination) -> dict:
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 -- e.g. KilledWorker: the task took down workers repeatedly
        return {"name": combo.name, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "traceback": "".join(traceback.format_exception(exc))}


def _executing(dask_worker) -> list[str]:
    """On a worker: the keys of the tasks it is executing now (not those queued on it)."""
    return [str(ts.key) for ts in dask_worker.state.executing]


def _running_keys(client) -> set[str]:
    try:
        return {key for keys in client.run(_executing, on_error="ignore").values()
                if isinstance(keys, list) for key in keys}
    except Exception:  # noqa: BLE001 -- a scheduler going away: nothing is known to run
        return set()


def _running(client, pending) -> int:
    keys = _running_keys(client)
    return sum(str(f.key) in keys for f in pending)


def _finish(spec: SweepSpec, sweep_dir: Path, outcomes: dict, stopped: bool, contact_sheet: bool,
            dashboard: str | None) -> SweepResult:
    """Record failures, write sweep.csv and the contact sheet."""
    for name, outcome in outcomes.items():
        if outcome["status"] == "failed":
            (sweep_dir / FAILED).mkdir(exist_ok=True)
            (sweep_dir / FAILED / f"{name}.txt").write_text(f"{outcome['error']}\n\n{outcome.get('traceback', '')}")
    rows = [table_row(spec, c, sweep_dir, outcomes.get(c.name)) for c in spec.combinations]
    table = sweep_dir / "sweep.csv"
    columns = ("name", *spec.swept_keys, *TABLE_COLUMNS[1:])
    tmp = table.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as fh:
        writer = csv.DictWriter(fh, columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, table)
    sheet = None
    if contact_sheet and rows:
        sheet = draw_contact_sheet(rank(rows), sweep_dir / "contact_sheet.png")
    failed = [r["name"] for r in rows if r["status"] == "failed"]
    return SweepResult(rows, stopped, table, sheet, dashboard, failed)


def table_row(spec: SweepSpec, combo: Combination, sweep_dir: Path, outcome: dict | None) -> dict:
    """One sweep.csv row: the combination's settings (resolved values), its status and its summary."""
    folder = sweep_dir / RUNS / combo.name
    row = {"name": combo.name, "folder": str(folder.relative_to(sweep_dir))}
    for key in spec.swept_keys:
        value = getattr(combo.config, key)
        row[key] = "" if value is None else value
    row.update(summary_row(folder))
    if outcome is not None and outcome["status"] == "failed":
        row.update(status="failed", error=outcome["error"])
    elif "status" not in row:
        row["status"] = "not started"
    return row
