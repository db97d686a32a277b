"""The bench calibration series (paper section 4.2) as a guided procedure.

Clear water first, then: add a known piece of filament, wait until it has dissolved, enter the cumulative
added mass, capture; repeat; fit the per-cell Beer-Lambert laws and save the calibration. The series is
stored as a run folder (``kind: calibration-series``) with a ``masses.csv`` (``file,added_mass_g``,
cumulative) beside ``frames.csv``, which is exactly what ``sfr calibrate-bench FOLDER`` reads too:
:func:`read_masses` and :func:`fit_series` are the one reader and the one fit of a series, for the guided
procedure, `sfr calibrate-bench` and the GUI alike.
"""
from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from analysis import BenchCalibration, CropGeometry, decode_image, fit_bench_calibration, read_cells
from labapp.acquisition.bench import Bench, BenchSession
from labapp.acquisition.engine import ABORT, Engine
from labapp.acquisition.events import AlarmKind, CalibrationLevel, Outcome, Phase, PromptKind, StateChanged
from labapp.acquisition.settings import (
    GRID,
    MIRROR_COL,
    SERIES_REDUCE,
    SERIES_SETTINGS,
    SETTLE,
    BathSettings,
    check_settings,
    from_record,
    to_record,
)
from labapp.errors import UsageError
from labapp.records.audit import Action
from labapp.records.audit import append as audit
from labapp.records.fileio import atomic_write
from labapp.records.manifests import MASSES_CSV
from labapp.records.storage import RunFolder, create_run

CALIBRATION_FILE = "bench_calibration.json"
MIN_LEVELS = 3
"""Concentration levels a calibration is fitted from at the least (clear water is the first)."""
MASS_COLUMNS = ("file", "added_mass_g")


def read_masses(folder: Path) -> tuple[list[Path], np.ndarray]:
    """The images and cumulative added masses (g) of a calibration series' ``masses.csv``.

    Raises
    ------
    UsageError
        Naming the file and row for: a missing file or column, a mass that is not a finite number >= 0,
        an image listed twice (duplicated or contradictory rows), a mass lower than the row before (masses
        are cumulative), or no rows.
    """
    path = Path(folder) / MASSES_CSV
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in MASS_COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                raise UsageError(f"{path}: missing column(s) {', '.join(missing)}; expected a header "
                                 f"{','.join(MASS_COLUMNS)}")
            rows = list(reader)
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror or exc}") from exc
    files: list[Path] = []
    masses: list[float] = []
    seen: dict[str, tuple[int, str]] = {}
    for line, row in enumerate(rows, start=2):
        name, text = (row.get("file") or "").strip(), (row.get("added_mass_g") or "").strip()
        if not name:
            raise UsageError(f"{path} row {line}: empty file name")
        try:
            mass = float(text)
        except ValueError:
            raise UsageError(f"{path} row {line}, added_mass_g: {text!r} is not a number (cumulative mass, g)") from None
        if not math.isfinite(mass) or mass < 0:
            raise UsageError(f"{path} row {line}, added_mass_g: {text!r}; expected a finite mass >= 0 g")
        if name in seen:
            first, first_mass = seen[name]
            what = "contradicts" if float(first_mass) != mass else "duplicates"
            raise UsageError(f"{path} row {line}: {name} is listed again ({what} row {first}, {first_mass} g); "
                             "list each image once")
        if masses and mass < masses[-1]:
            raise UsageError(f"{path} row {line}, added_mass_g: {mass} g is below the row before ({masses[-1]} g); "
                             "masses are cumulative (never decreasing)")
        seen[name] = (line, text)
        files.append(Path(folder) / name)
        masses.append(mass)
    if not files:
        raise UsageError(f"{path} lists no images")
    return files, np.array(masses)


def fit_series(files: list[Path], masses_g: np.ndarray, geometry: CropGeometry, water_g: float,
               camera: dict[str, str] | None = None, reduce: int = 1,
               progress: Callable[[int, int], None] | None = None) -> BenchCalibration:
    """Fit the per-cell Beer-Lambert calibration (paper section 4.2) of a series of images.

    Parameters
    ----------
    files : list of Path
        The images, in series order.
    masses_g : (L,) ndarray of float
        Cumulative added mass when each image was taken, g; concentration = mass / water_g * 1000 g/kg.
    geometry : CropGeometry
    water_g : float
        Water mass, g.
    camera : dict, optional
        Camera settings to record.
    reduce : int
        Decode downscaling.
    progress : callable, optional
        ``progress(done, total)`` after each image; it may raise ``KeyboardInterrupt`` to stop there.

    Raises
    ------
    analysis.AnalysisError
        For an unreadable or wrong-sized image or too few levels.
    """
    missing = [str(f) for f in files if not Path(f).is_file()]
    if missing:
        raise UsageError(f"{len(missing)} image(s) of the series do not exist: {', '.join(missing[:3])}"
                         + (" ..." if len(missing) > 3 else ""))
    shape = image_shape(files[0])
    read = []
    for f in files:
        read.append(read_cells(f, geometry, reduce=reduce, expect_shape=shape))
        if progress is not None:
            progress(len(read), len(files))
    cells = np.array(read)
    conc = np.asarray(masses_g, float) / water_g * 1000.0
    return fit_bench_calibration(cells, conc, geometry, water_g, camera or {}, image_shape=shape, reduce=reduce)


@dataclass(frozen=True)
class SeriesConfig:
    """Settings of a calibration series. Masses in g (cumulative), times in s, crop in px; the bath in ``bath``.

    ``masses_g`` given: the series adds these by itself (simulated bench) and waits ``settle_s`` after each;
    empty: the operator is asked for each mass (and ``settle_s`` is waited too: 0 on a real bench, where the
    operator waits for the piece to dissolve). Either way ``Bench.on_add_mass`` (a simulated bench) is told.
    Ranges and defaults are declared in :mod:`labapp.acquisition.settings` (:data:`SERIES_SETTINGS`).
    """

    crop: tuple[int, int, int]
    name: str = "calibration"
    grid: int = GRID.default
    mirror_col: float | None = MIRROR_COL.default
    reduce: int = SERIES_REDUCE.default
    masses_g: tuple[float, ...] = ()
    settle_s: float = SETTLE.default
    bath: BathSettings = field(default_factory=BathSettings)

    def __post_init__(self) -> None:
        check_settings(self, SERIES_SETTINGS)
        if len(self.crop) != 3 or min(self.crop) < 0 or self.crop[2] < self.grid:
            raise UsageError(f"SeriesConfig.crop must be (x, y, size) px with size >= grid, got {self.crop}")
        if any(b <= a for a, b in zip((0.0,) + self.masses_g, self.masses_g)):
            raise UsageError(f"masses {', '.join(f'{m:g}' for m in self.masses_g)} g (--masses): each must be above the "
                             f"one before and above 0, the cumulative filament added to the water at each level")
        if self.masses_g and len(self.masses_g) + 1 < MIN_LEVELS:
            raise UsageError(f"masses {', '.join(f'{m:g}' for m in self.masses_g)} g: clear water and "
                             f"{len(self.masses_g)} addition(s) make {len(self.masses_g) + 1} levels; a calibration "
                             f"needs {MIN_LEVELS}: give at least {MIN_LEVELS - 1} cumulative masses (--masses)")

    def to_dict(self) -> dict[str, Any]:
        """The settings as stored under ``config`` in ``run.json`` (the bath's fields alongside the series')."""
        return to_record(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SeriesConfig:
        """Rebuild a config stored in ``run.json`` (flat, or the bath under ``bath``; unknown keys ignored)."""
        return from_record(cls, data)

    def geometry(self) -> CropGeometry:
        """The crop geometry the calibration is fitted for."""
        x, y, size = self.crop
        return CropGeometry(x, y, size, grid=self.grid, mirror_col=self.mirror_col)


@dataclass(frozen=True)
class RedoLevel:
    """An answer to the mass prompt: capture the last level again (a bubble, a hand in the picture); the new
    frame replaces the level's capture in ``masses.csv``, the old one stays in the folder and the
    replacement is written to ``events.log``."""


class CalibrationProcedure:
    """Capture a calibration series into a new folder under ``data_dir`` and fit it.

    The operator answers each mass prompt with the next cumulative mass (above the last one: a mass already
    captured is refused and asked again, nothing is captured), :class:`RedoLevel` to capture the last level
    again, or an empty answer to finish. After a complete run, :attr:`calibration_path` is the saved
    calibration (None if fewer than 3 levels).
    """

    name = "calibration"

    def __init__(self, config: SeriesConfig, bench: Bench, data_dir: Path) -> None:
        self.config, self.bench, self.data_dir = config, bench, Path(data_dir)
        self.run: RunFolder | None = None
        self.session: BenchSession | None = None
        self.masses: list[tuple[str, float]] = []
        self.calibration_path: Path | None = None

    def startup(self, engine: Engine) -> None:
        """Create the series folder and connect the devices."""
        cfg = self.config
        self.run = create_run(self.data_dir, cfg.name, dict(kind="calibration-series", config=cfg.to_dict(),
                                                           water_g=cfg.bath.water_g, simulated=self.bench.simulated))
        engine.emit(StateChanged(Phase.OPENED, folder=str(self.run.path)))
        self.session = BenchSession(self.bench, engine, self.run, keepalive_s=cfg.bath.keepalive_s)
        self.session.t0_unix_s = engine.clock.now()
        if self.bench.on_new_beaker is not None:
            self.bench.on_new_beaker()
        self.session.connect(cfg.bath.setpoint_c, cfg.bath.speed_rpm)

    def execute(self, engine: Engine) -> None:
        """Heat, stir, then one capture per mass level; fit when the operator (or the list) ends."""
        cfg, session = self.config, self.session
        session.wait_bath(cfg.bath)
        session.start_stirring()
        engine.emit(StateChanged(Phase.CALIBRATING))
        mass = 0.0
        auto = list(cfg.masses_g)
        capture = True
        while not engine.should_stop():
            if capture:
                self._capture_level(engine, mass)
            capture = True
            if cfg.masses_g:
                if not auto:
                    break
                mass = auto.pop(0)
                if self.bench.on_add_mass is not None:
                    self.bench.on_add_mass(mass)
                session.note("info", "mass", f"{mass:.4f} g of filament added in total (simulated)")
                engine.clock.sleep(cfg.settle_s, engine.should_stop)
                continue
            answer = engine.ask(PromptKind.ADDED_MASS, f"Add filament, wait until it has dissolved, then enter the "
                                f"cumulative added mass in g (now {mass:g} g); leave empty to finish and fit.")
            if answer is None or answer == "":
                break
            if isinstance(answer, RedoLevel):
                self._redo_level(engine, mass)
                capture = False
                continue
            new = float(answer)
            if not new > mass:
                captured = any(m == new for _, m in self.masses)
                session.note("warning", "mass", f"{new:g} g is {'a level already captured' if captured else 'below'} "
                             f"the cumulative {mass:g} g; nothing captured. Enter a higher cumulative mass, or redo "
                             "the last level")
                capture = False
                continue
            mass = new
            if self.bench.on_add_mass is not None:
                self.bench.on_add_mass(mass)
            engine.clock.sleep(cfg.settle_s, engine.should_stop)
        if engine.stop_reason == ABORT:
            session.note("info", "calibration", f"aborted with {len(self.masses)} levels captured; not fitted")
            return
        if len(self.masses) >= MIN_LEVELS:
            try:
                self._fit()
            except Exception as exc:
                session.note("error", "calibration", f"the fit of {len(self.masses)} levels failed: "
                             f"{type(exc).__name__}: {exc}", AlarmKind.FIT_FAILED)
                raise
        else:
            session.note("warning", "calibration", f"only {len(self.masses)} levels captured; {MIN_LEVELS} are needed to fit",
                         AlarmKind.FIT_FAILED)

    def shutdown(self, engine: Engine, outcome: Outcome) -> None:
        """Heating off, devices closed, final status written."""
        if self.session is not None:
            self.session.close()
        if self.run is not None:
            self.run.finish(Outcome.STOPPED if outcome == Outcome.INTERRUPTED else outcome)   # a series never resumes
            self.run.close()

    def _redo_level(self, engine: Engine, mass_g: float) -> None:
        if not self.masses or self.masses[-1][1] != mass_g:
            self.session.note("warning", "calibration", f"no capture at {mass_g:g} g to redo")
            return
        old = self.masses[-1][0]
        if self._capture_level(engine, mass_g, replace=True):
            self.session.note("info", "redo", f"level {mass_g:g} g captured again by the operator: "
                              f"{self.masses[-1][0]} replaces {old} in {MASSES_CSV} ({old} stays in the folder)")

    def _capture_level(self, engine: Engine, mass_g: float, replace: bool = False) -> bool:
        cap = self.session.capture() or self.session.capture()
        if cap is None:
            self.session.note("warning", "calibration", f"no frame at {mass_g} g: the camera failed twice")
            return False
        index = len(self.run.frames)
        name = f"cal_{index:03d}{Path(cap.file_name).suffix.lower() or '.jpg'}"
        self.run.add_frame(name, cap.data, self.session.t_s(cap.t_unix_s), cap.t_unix_s)
        if replace:
            self.masses.pop()
        self.masses.append((name, mass_g))
        rows = ",".join(MASS_COLUMNS) + "\n" + "".join(f"{f},{m:.6f}\n" for f, m in self.masses)
        atomic_write(self.run.path / MASSES_CSV, rows.encode())
        self.run.update()  # seals the new masses (labapp.records.seal)
        conc = mass_g / (self.config.bath.water_g / 1000.0)
        engine.emit(CalibrationLevel(index, name, str(self.run.path / name), self.session.t_s(), mass_g, conc,
                                     len(self.masses)))
        self.session.note("info", "level", f"{name}: {mass_g:g} g added, {conc:.4f} g/kg")
        return True

    def _fit(self) -> None:
        cfg = self.config
        conc = np.array([m for _, m in self.masses]) / (cfg.bath.water_g / 1000.0)
        cal = fit_series([self.run.path / f for f, _ in self.masses], np.array([m for _, m in self.masses]),
                         cfg.geometry(), cfg.bath.water_g, reduce=cfg.reduce,
                         camera={k: str(v) for k, v in dataclasses.asdict(self.bench.camera_settings).items()})
        self.calibration_path = self.run.path / CALIBRATION_FILE
        tmp = self.run.path / f".{CALIBRATION_FILE}.fit"
        cal.save(tmp)
        self.run.add_file(CALIBRATION_FILE, tmp.read_bytes())
        tmp.unlink()
        good = int(np.count_nonzero(cal.good))
        self.run.update(calibration_file=CALIBRATION_FILE)
        self.session.note("info", "calibration", f"fitted {len(self.masses)} levels "
                          f"({conc.min():.3g}..{conc.max():.3g} g/kg), {good}/{cal.good.size} good cells; "
                          f"saved {CALIBRATION_FILE}")
        audit(self.run.path, Action.CALIBRATE, f"bench calibration fitted from {len(self.masses)} levels, {good}/"
              f"{cal.good.size} good cells: {CALIBRATION_FILE} (SHA-256 {self.run.record.files[CALIBRATION_FILE]})")


def image_shape(path: Path) -> tuple[int, int]:
    """(H, W) of an image file, px, from its header (decoded when Pillow cannot read it, e.g. camera raw)."""
    try:
        with Image.open(path) as image:
            return image.height, image.width
    except OSError:
        return decode_image(path).shape[:2]
