"""The simulated bench: SimulatedCamera + Heidolph emulator + a dissolving sample object, on one clock.

The object's release comes from the forward simulator (``design.forward``) and is mapped to physical units
with fixed nominal constants (the real simulation-to-bench calibration, paper section 4.3, is a later
issue):

- print density 1.32 g/cm^3 (paper section 4.1): released g = released mm^3 x 1.32e-3;
- dissolution rate :data:`SECONDS_PER_MM` s per mm of dissolved depth: t_s = tau_mm x SECONDS_PER_MM,
  chosen so that a ~1.75 g object (paper section 5.1) takes about 3 hours;
- 500 g of water: concentration g/kg = released g / 0.5 kg.

Everything runs on the engine's clock: the camera renders the concentration at ``clock.now()``, and the
emulated plate's thermal model runs at the same speed (``ScaledClock``) or on the clock itself
(``SteppedClock``, whose time jumps, so the plate's "PC Err" connection check is disabled there).
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.camera import SimulatedCamera
from drivers.camera.base import Capture, CameraSettings
from drivers.hotplate import HeidolphHotplate
from drivers.sim import BenchScene
from drivers.sim.heidolph_emulator import HeidolphEmulator
from labapp.bench import Bench
from labapp.clock import Clock, ScaledClock, SteppedClock, WallClock
from labapp.storage import FRAMES_CSV, read_run

log = logging.getLogger(__name__)

DENSITY_G_PER_MM3 = 1.32e-3
"""Print density of the AquaSys 120 prints, 1.32 g/cm^3 (paper section 4.1), in g/mm^3."""
SECONDS_PER_MM = 1600.0
"""Nominal dissolution rate: seconds per mm of dissolved depth (tau)."""
WATER_G = 500.0
"""Water in the beaker, g (paper section 4.2)."""
SAMPLE_MASS_G = 1.75
"""Mass the shipped sample objects are scaled to, g (paper section 5.1)."""
SCENE = BenchScene(width=960, height=640, water_g=WATER_G)
"""The simulated bench picture: the renderer's default scene at 960 x 640 px (renders in about half the time
of its 1200 x 800 default; the analysis works in full-resolution px either way)."""


@dataclass(frozen=True, eq=False)
class SampleRelease:
    """A dissolving object's cumulative release in physical units.

    Attributes
    ----------
    name : str
    t_s : (K,) ndarray of float, s since the drop
    released_g : (K,) ndarray of float, g
    """

    name: str
    t_s: np.ndarray
    released_g: np.ndarray

    @property
    def mass_g(self) -> float:
        """Total mass released when fully dissolved, g."""
        return float(self.released_g[-1])

    @property
    def duration_s(self) -> float:
        """Time to dissolve completely, s."""
        return float(self.t_s[-1])

    def conc_g_per_kg(self, t_since_drop_s: float, water_g: float = WATER_G) -> float:
        """Concentration at a time after the drop (0 before it), g/kg."""
        if t_since_drop_s <= 0:
            return 0.0
        return float(np.interp(t_since_drop_s, self.t_s, self.released_g)) / (water_g / 1000.0)

    @classmethod
    def from_simulation(cls, name: str, tau_mm: np.ndarray, released_mm3: np.ndarray) -> SampleRelease:
        """Map a simulated curve (tau in mm, released mm^3) to s and g with the nominal constants."""
        return cls(name, np.asarray(tau_mm, float) * SECONDS_PER_MM,
                   np.asarray(released_mm3, float) * DENSITY_G_PER_MM3)


def sample_release(shape: str = "pill", mass_g: float = SAMPLE_MASS_G, resolution: int = 48) -> SampleRelease:
    """Simulate a shipped sample object scaled to ``mass_g`` (g) and map its release to s and g.

    Parameters
    ----------
    shape : str
        A name of ``design.shapes.SAMPLE_SHAPES``.
    mass_g : float
        Mass of the printed object, g (scales the mesh at 1.32 g/cm^3).
    resolution : int
        Voxels along the longest side for the forward simulation.
    """
    from design.pipeline import simulate_mesh
    from design.shapes import sample_shape

    mesh = sample_shape(shape)
    scale = (mass_g / DENSITY_G_PER_MM3 / mesh.volume) ** (1.0 / 3.0)
    mesh = mesh.copy()
    mesh.apply_scale(scale)
    release = simulate_mesh(mesh, resolution=resolution)
    log.info("sample %s: %.3f g, %.0f mm^3, dissolves in %.0f s (tau %.2f mm)", shape, mass_g, mesh.volume,
             release.tau_mm[-1] * SECONDS_PER_MM, release.tau_mm[-1])
    return SampleRelease.from_simulation(shape, release.tau_mm, release.released_mm3)


class _ClockedCamera:
    """The SimulatedCamera reporting capture times on the engine's clock (it stamps wall time itself)."""

    def __init__(self, camera: SimulatedCamera, clock: Clock) -> None:
        self.camera, self.clock = camera, clock

    def connect(self) -> None:
        self.camera.connect()

    def configure(self, settings: CameraSettings) -> dict[str, str]:
        return self.camera.configure(settings)

    def capture(self) -> Capture:
        cap = self.camera.capture()
        return dataclasses.replace(cap, t_unix_s=self.clock.now())

    def close(self) -> None:
        self.camera.close()


class SimulatedBench:
    """A complete simulated bench on ``clock``; :meth:`bench` hands it to any procedure.

    Parameters
    ----------
    clock : Clock
        The engine's clock.
    release : SampleRelease, optional
        The object that dissolves after the drop (default: :func:`sample_release` of ``sample``).
    sample : str
        Shipped sample shape simulated when ``release`` is None.
    scene : BenchScene
        What the camera sees (default :data:`SCENE`).
    with_hotplate : bool
        Start the Heidolph emulator on a pseudo-terminal and talk to it with the real driver.
    seed : int
        Seed of image noise and plate read-out noise.
    """

    def __init__(self, clock: Clock, release: SampleRelease | None = None, sample: str = "pill",
                 scene: BenchScene | None = None, with_hotplate: bool = True, seed: int = 0) -> None:
        self.clock = clock
        self.release = release if release is not None else sample_release(sample)
        self.scene = scene or SCENE
        self.t_drop: float | None = None
        self.added_mass_g = 0.0
        self.camera = SimulatedCamera(lambda _t: self.conc_at(self.clock.now()), self.scene, seed=seed,
                                      clock=clock.now, deadline_s=2.0)
        self.emulator: HeidolphEmulator | None = None
        self.hotplate: HeidolphHotplate | None = None
        if with_hotplate:
            if isinstance(clock, SteppedClock):
                self.emulator = HeidolphEmulator(clock=clock.now, watchdog_s=1e12, seed=seed)
            else:
                speed = clock.speed if isinstance(clock, ScaledClock) else 1.0
                self.emulator = HeidolphEmulator(speed=speed, seed=seed)
            self.hotplate = HeidolphHotplate(self.emulator.start(), keep_alive=False)

    @staticmethod
    def default_crop() -> tuple[int, int, int]:
        """The default scene's crop (x, y, size), px."""
        return SCENE.default_crop()

    def conc_at(self, t_unix_s: float) -> float:
        """True concentration in the beaker at a clock time, g/kg (calibration additions + the object)."""
        conc = self.added_mass_g / (self.scene.water_g / 1000.0)
        if self.t_drop is not None:
            conc += self.release.conc_g_per_kg(t_unix_s - self.t_drop, self.scene.water_g)
        return conc

    def drop(self, t_unix_s: float) -> None:
        """The object goes in at ``t_unix_s`` (clock time)."""
        self.t_drop = t_unix_s

    def add_mass(self, total_g: float) -> None:
        """Calibration: the cumulative dissolved filament mass is now ``total_g`` g."""
        self.added_mass_g = total_g

    def bench(self) -> Bench:
        """The devices and hooks, for a procedure."""
        return Bench(_ClockedCamera(self.camera, self.clock), self.hotplate, CameraSettings(), simulated=True,
                     on_drop=self.drop, on_add_mass=self.add_mass,
                     description=f"simulated bench ({self.release.name}, {self.release.mass_g:.2f} g, "
                                 f"x{self.clock.speed:g} time)")

    # -- faults ------------------------------------------------------------------------------------------
    def camera_busy(self, n: int = 1) -> None:
        """The next ``n`` captures fail as a busy camera would."""
        self.camera.inject_busy(n)

    def corrupt_frames(self, n: int = 1) -> None:
        """The next ``n`` frames arrive truncated."""
        self.camera.inject_corrupt(n)

    def drop_hotplate_link(self, down_s: float) -> None:
        """The hotplate's serial link goes dead for ``down_s`` s (emulator clock)."""
        if self.emulator is not None:
            self.emulator.drop_link(down_s)

    def close(self) -> None:
        """Stop the emulator (the procedure has closed the driver already)."""
        if self.emulator is not None:
            self.emulator.stop()
            self.emulator = None


def resume_clock(folder: Path, speed: float | None) -> Clock:
    """The clock a simulated run continues on after a crash: simulated time went on while the process was
    down (downtime x speed after the last frame); real runs use the wall clock."""
    if speed is None or speed == 1:
        return WallClock()
    snap = read_run(folder)
    last = snap.frames[-1].t_unix_s if snap.frames else snap.meta.get("t0_unix_s", time.time())
    down_wall_s = max(time.time() - (folder / FRAMES_CSV).stat().st_mtime, 0.0)
    start = last + (down_wall_s * speed if math.isfinite(speed) else 0.0)
    return SteppedClock(start) if math.isinf(speed) else ScaledClock(speed, start_s=start)
