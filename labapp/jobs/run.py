"""Start or resume an acquisition run: the procedure the engine walks (`sfr run`, `sfr run --resume`)."""
from __future__ import annotations

from pathlib import Path

from labapp.errors import UsageError
from labapp.records.outpaths import check_data_dir


def new_run(config, bench, data_dir: str | Path, calibration=None):
    """A :class:`labapp.acquisition.procedures.RunProcedure` for a new run in ``data_dir`` (checked, nothing written).

    Raises
    ------
    UsageError
        If ``data_dir`` is a file or lies inside a record or another command's folder.
    """
    from labapp.acquisition.procedures import RunProcedure

    return RunProcedure(config, bench, check_data_dir(data_dir), calibration)


def resumable(folder: str | Path):
    """The snapshot of an interrupted acquisition run; anything else is refused without writing a byte.

    Raises
    ------
    UsageError
        Naming what ``folder`` is instead: not a run folder, a calibration series or other kind, a run
        that finished (complete, stopped, aborted, failed), or one still being written.
    """
    from labapp.records.outpaths import folder_kind
    from labapp.records.storage import StorageError, read_run

    folder = Path(folder)
    try:
        snap = read_run(folder)
    except StorageError:
        kind = folder_kind(folder)
        what = "does not exist" if not folder.exists() else \
            f"is not a run folder ({'no run.json' if kind is None or kind in ('other', 'images') else kind})"
        raise UsageError(f"{folder} {what}; only an interrupted acquisition run can be resumed") from None
    kind = snap.meta.get("kind", "run")
    if kind != "run":
        raise UsageError(f"{folder} is a {kind or 'folder of unknown kind'}, not an acquisition run; only an "
                         "interrupted acquisition run can be resumed")
    if snap.live:
        raise UsageError(f"{folder} is being written by process {snap.meta.get('writer_pid')}; it is not "
                         "interrupted")
    if snap.status != "interrupted":
        raise UsageError(f"{folder} finished ({snap.status}); only an interrupted run can be resumed. "
                         "A finished run is a record: start a new run instead")
    if "config" not in snap.meta:
        raise UsageError(f"{folder}/run.json has no run settings (config); it cannot be resumed")
    return snap


def resume_run(folder: str | Path, bench, calibration=None):
    """A :class:`labapp.acquisition.procedures.RunProcedure` continuing the interrupted run in ``folder``.

    Call :func:`resumable` first to learn from ``run.json`` whether the run was simulated (and build the
    matching bench); this checks again and refuses a bench of the other kind.

    Raises
    ------
    UsageError
        As :func:`resumable`, or when the bench is simulated and the run was not (or the reverse).
    """
    from labapp.acquisition.procedures import RunProcedure

    snap = resumable(folder)
    if bool(snap.meta.get("simulated")) != bool(bench.simulated):
        raise UsageError(f"{folder} was recorded on a {'simulated' if snap.meta.get('simulated') else 'real'} "
                         f"bench; it cannot be resumed on a {'simulated' if bench.simulated else 'real'} one")
    return RunProcedure.resume(Path(folder), bench, calibration)
