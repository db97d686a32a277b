"""Record a bench calibration series: the procedure the engine walks (`sfr calibrate-bench --record`, the GUI's
calibration wizard)."""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from labapp.acquisition.bench import Bench
from labapp.acquisition.calseries import CalibrationProcedure, SeriesConfig
from labapp.acquisition.clock import Clock
from labapp.acquisition.settings import GRID, SERIES_REDUCE, SETTLE, WATER, BathSettings
from labapp.acquisition.simbench import SCENE, SampleRelease, SimulatedBench
from labapp.errors import UsageError
from labapp.records.outpaths import check_data_dir


def new_series(bench: Bench, data_dir: str | Path, crop: Sequence[int], *, bath: BathSettings | None = None,
               masses_g: Sequence[float] = (), settle_s: float | None = None, name: str = "calibration",
               grid: int = GRID.default, mirror_col: float | None = None, reduce: int = SERIES_REDUCE.default,
               clock_speed: float = 1.0) -> CalibrationProcedure:
    """A :class:`labapp.acquisition.calseries.CalibrationProcedure` recording a series into a new folder in
    ``data_dir`` (checked, nothing written).

    Parameters
    ----------
    bench : Bench
        The devices (a real bench or :meth:`labapp.acquisition.simbench.SimulatedBench.bench`).
    data_dir : str or Path
        Where the series folder is created.
    crop : (3,) sequence of int
        x, y, size of the square crop inside the beaker, px.
    bath : BathSettings, optional
        Water, temperature and stirring (default :class:`BathSettings`).
    masses_g : sequence of float
        Cumulative masses the bench adds by itself (a simulated bench), g; empty: the operator enters each.
    settle_s : float, optional
        Wait after each addition, s; default :data:`labapp.acquisition.settings.SETTLE` on a simulated bench,
        0 on a real one (the operator enters each mass once the piece has dissolved).
    name, grid, mirror_col, reduce
        As :class:`SeriesConfig`.
    clock_speed : float
        Speed of the engine's clock (``inf`` for an instant clock: the bath is checked in longer steps).

    Raises
    ------
    UsageError
        If ``data_dir`` is a file or lies inside a record or another command's folder, ``masses_g`` are given
        for a bench that cannot add them, or a setting is out of its range.
    """
    data_dir = check_data_dir(data_dir)
    if masses_g and bench.on_add_mass is None:
        raise UsageError(f"masses {tuple(masses_g)} g: only the simulated bench adds filament by itself; on this "
                         "bench leave them out and enter each cumulative mass when asked")
    if settle_s is None:
        settle_s = SETTLE.default if bench.simulated else 0.0
    config = SeriesConfig(crop=tuple(int(v) for v in crop), name=name, grid=grid, mirror_col=mirror_col,
                          reduce=reduce, masses_g=tuple(float(m) for m in masses_g), settle_s=settle_s,
                          bath=(bath or BathSettings()).on_clock(clock_speed))
    return CalibrationProcedure(config, bench, data_dir)


def simulated_series_bench(clock: Clock, water_g: float = WATER.default, seed: int = 0):
    """A simulated bench for a calibration series in ``water_g`` g of water: nothing dissolves but the added
    filament, and no object pieces or bubbles drift through the crop (each piece has dissolved before its
    frame is taken).

    Returns the :class:`labapp.acquisition.simbench.SimulatedBench` (close it when done).
    """
    no_object = SampleRelease("none", np.array([0.0, 1.0]), np.zeros(2))
    return SimulatedBench(clock, release=no_object, scene=dataclasses.replace(SCENE, intrusion_probability=0.0),
                          seed=seed, water_g=water_g)
