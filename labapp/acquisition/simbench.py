"""The simulated bench: SimulatedCamera + Heidolph emulator + a dissolving sample object, on one clock.

The object dissolves by the bench's own physics (:mod:`labapp.acquisition.printworld`: anisotropic
erosion, a print a little larger or smaller than its mesh, channels shut by swelling, a wetting lag),
computed with no code of the forward model (a material without print physics, for tests of the
calibration's arithmetic, dissolves exactly as the forward model computes), and is mapped to physical units by a hidden material
(:class:`Material`, drawn from a seed): its dissolution rate (s per mm of in-plane erosion depth), print
density and print physics differ from any constant of the code, and every printed object deviates from
the material by a few percent (its own seeded draw), as real prints do. Nothing in the calibration reads them: the
simulation-to-bench calibration (``sfr calibrate-sim``) has to recover them from the images. A sample
object keeps its truth in :attr:`SampleRelease.truth` for tests and the demo's ``truth.json``.

Everything runs on the engine's clock: the camera renders the concentration at ``clock.now()``, and the
emulated plate's thermal model runs at the same speed (``ScaledClock``) or on the clock itself
(``SteppedClock``, whose time jumps, so the plate's "PC Err" connection check is disabled there).
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from design.forward.reference import design_lattice, reference_release
from design.geometry.shapes import sample_shape
from drivers.camera import SimulatedCamera
from drivers.camera.base import CameraSettings, Capture
from drivers.hotplate import HeidolphHotplate
from drivers.sim import BenchScene
from drivers.sim.heidolph_emulator import HeidolphEmulator
from labapp.acquisition.bench import Bench
from labapp.acquisition.clock import Clock, ScaledClock, SteppedClock, WallClock
from labapp.acquisition.printworld import WORLD_RESOLUTION, PrintPhysics
from labapp.acquisition.settings import WATER
from labapp.acquisition.worldcache import cached_world_release
from labapp.records.manifests import FRAMES_CSV, read_run

log = logging.getLogger(__name__)

WATER_G = WATER.default
"""Water in the simulated beaker, g: the declared default (:data:`labapp.acquisition.settings.WATER`)."""
SCENE = BenchScene(width=960, height=640, water_g=WATER_G)
"""The simulated bench picture: the renderer's default scene at 960 x 640 px (renders in about half the time
of its 1200 x 800 default; the analysis works in full-resolution px either way)."""
MATERIAL_SEED = 20221206
"""Seed of the simulated bench's material draw."""
BARRIER_STREAM = 47
"""Second seed word of the barrier speed's own draw (so that the drug material's draw is unchanged)."""


@dataclass(frozen=True)
class Material:
    """The simulated bench's hidden material.

    Attributes
    ----------
    seconds_per_mm : float
        Dissolution: seconds per mm of dissolved depth (tau).
    density_g_per_cm3 : float
        Print density.
    rate_spread, density_spread : float
        Relative standard deviation of each printed object's rate and density around the material's.
    barrier_speed : float
        The clear barrier material's erosion speed over the drug material's (two-material prints; it absorbs no
        light, so the camera sees only the drug).
    seed : int
        The bench's seed: its printed objects' own deviations (:meth:`printed`) are drawn from it, so that each
        bench is one lab with its own prints.
    physics : PrintPhysics or None
        How its prints dissolve (:mod:`labapp.acquisition.printworld`). None: exactly as the isotropic
        forward model computes at the sample's resolution, for tests of the calibration's arithmetic,
        where the model must be right.
    """

    seconds_per_mm: float
    density_g_per_cm3: float
    rate_spread: float = 0.015
    density_spread: float = 0.02
    physics: PrintPhysics | None = None
    barrier_speed: float = 0.35
    seed: int = MATERIAL_SEED

    @classmethod
    def draw(cls, seed: int = MATERIAL_SEED) -> Material:
        """A material with a rate of 1000-2400 s/mm (a ~1.7 g object dissolves in 1.5-3.5 h), a print
        density of 1.15-1.45 g/cm^3 and print physics drawn by :meth:`PrintPhysics.draw`."""
        rng = np.random.default_rng(seed)
        barrier = float(np.random.default_rng([seed, BARRIER_STREAM]).uniform(0.2, 0.6))
        return cls(float(rng.uniform(1000.0, 2400.0)), float(rng.uniform(1.15, 1.45)),
                   physics=PrintPhysics.draw(seed), barrier_speed=barrier, seed=seed)

    def printed(self, index: int) -> tuple[float, float]:
        """The ``index``-th printed object's own (seconds_per_mm, g_per_mm3), drawn from the bench's seed."""
        rng = np.random.default_rng([self.seed, index])
        rate, dens = rng.standard_normal(2)
        return (float(self.seconds_per_mm * (1.0 + self.rate_spread * rate)),
                float(self.density_g_per_cm3 * 1e-3 * (1.0 + self.density_spread * dens)))


@dataclass(frozen=True, eq=False)
class SampleRelease:
    """A dissolving object's cumulative release in physical units.

    Attributes
    ----------
    name : str
    t_s : (K,) ndarray of float, s since the drop
    released_g : (K,) ndarray of float, g
    truth : dict
        Hidden ground truth of the simulated object (``seconds_per_mm``, ``g_per_mm3``, ``volume_mm3``,
        ``mass_g``); for tests and the demo's ``truth.json``, never for the calibration.
    """

    name: str
    t_s: np.ndarray
    released_g: np.ndarray
    truth: dict = field(default_factory=dict)

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
    def from_simulation(cls, name: str, tau_mm: np.ndarray, released_mm3: np.ndarray, seconds_per_mm: float,
                        g_per_mm3: float, lag_s: float = 0.0) -> SampleRelease:
        """Map a release curve (erosion depth in mm, released mm^3) to s and g with an object's own scales,
        starting ``lag_s`` after the drop."""
        vol = np.asarray(released_mm3, float)
        truth = {"seconds_per_mm": seconds_per_mm, "g_per_mm3": g_per_mm3, "volume_mm3": float(vol[-1]),
                 "mass_g": float(vol[-1] * g_per_mm3)}
        return cls(name, lag_s + np.asarray(tau_mm, float) * seconds_per_mm, vol * g_per_mm3, truth)


def sample_release(shape: str = "pill", index: int = 0, resolution: int = WORLD_RESOLUTION,
                   material: Material | None = None, mesh=None, barrier=None) -> SampleRelease:
    """The ``index``-th print of a shipped sample object dissolving on the bench, in its hidden material.

    Parameters
    ----------
    shape : str
        A name of ``design.geometry.shapes.SAMPLE_SHAPES`` (each 1326 mm^3 as designed).
    index : int
        Which print: each has its own few-percent deviation of rate and density.
    resolution : int
        Voxels along the longest side of the bench's own release computation
        (:func:`labapp.acquisition.printworld.world_release`, kept in the user's cache by
        :mod:`labapp.acquisition.worldcache`, or the forward model's grid for a material without print
        physics).
    material : Material, optional
        Default :meth:`Material.draw`.
    mesh : trimesh.Trimesh, optional
        The print's mesh, named ``shape`` (default: the sample ``shape``'s).
    barrier : trimesh.Trimesh, optional
        A clear barrier printed with it (the drug wins where they overlap), eroding at the material's
        ``barrier_speed``: the drug's release by the two-material reference evaluator, with the print physics'
        build-direction anisotropy and wetting lag (its offset and swelling are one material's).
    """
    material = material or Material.draw()
    mesh = sample_shape(shape) if mesh is None else mesh
    seconds_per_mm, g_per_mm3 = material.printed(index)
    physics = material.physics
    if barrier is not None:
        return _barrier_release(shape, mesh, barrier, material, seconds_per_mm, g_per_mm3)
    if physics is None:
        # the release the calibration's model gives with identity physics: the exact one (reference evaluator)
        end = 0.5 * float(np.max(mesh.extents))   # no point of the solid lies deeper
        model = reference_release(mesh, np.linspace(0.0, end, 801), cells=design_lattice(resolution))
        whole = min(int(np.searchsorted(model.tau_mm, model.total_time_mm)) + 1, model.tau_mm.size)   # to its end
        release = SampleRelease.from_simulation(shape, model.tau_mm[:whole], model.released_mm3[:whole], seconds_per_mm,
                                                g_per_mm3)
    else:
        world = cached_world_release(mesh, physics, resolution=resolution)
        release = SampleRelease.from_simulation(shape, world.tau_mm, world.released_mm3, seconds_per_mm, g_per_mm3,
                                                lag_s=physics.wetting_lag_s)
        release.truth["physics"] = dataclasses.asdict(physics)
    log.info("sample %s #%d: %.3f g, dissolves in %.0f s", shape, index, release.mass_g, release.duration_s)
    return release


def _barrier_release(shape: str, mesh, barrier, material: Material, seconds_per_mm: float,
                     g_per_mm3: float) -> SampleRelease:
    """A drug print with a clear barrier dissolving on the bench: only the drug darkens the water."""
    from design.forward.twomaterial_reference import two_material_reference_release

    physics = material.physics
    model = two_material_reference_release(mesh, barrier, material.barrier_speed,
                                           anisotropy=1.0 if physics is None else physics.anisotropy)
    release = SampleRelease.from_simulation(shape, model.tau_mm, model.released_mm3, seconds_per_mm, g_per_mm3,
                                            lag_s=0.0 if physics is None else physics.wetting_lag_s)
    release.truth["barrier_speed"] = material.barrier_speed
    log.info("sample %s with a barrier (speed %g): %.3f g, dissolves in %.0f s", shape, material.barrier_speed,
             release.mass_g, release.duration_s)
    return release


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
    water_g : float, optional
        Water in the beaker, g (default: the scene's); a run's or series' bath water on this bench.
    with_hotplate : bool
        Start the Heidolph emulator on a pseudo-terminal and talk to it with the real driver.
    seed : int
        Seed of image noise and plate read-out noise.
    """

    def __init__(self, clock: Clock, release: SampleRelease | None = None, sample: str = "pill",
                 scene: BenchScene | None = None, with_hotplate: bool = True, seed: int = 0,
                 water_g: float | None = None) -> None:
        self.clock = clock
        self.release = release if release is not None else sample_release(sample)
        self.scene = scene or SCENE
        if water_g is not None:
            self.scene = dataclasses.replace(self.scene, water_g=water_g)
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

    def new_beaker(self) -> None:
        """Fresh clear water: no object, no filament (each new run or series starts with one)."""
        self.t_drop = None
        self.added_mass_g = 0.0

    def bench(self) -> Bench:
        """The devices and hooks, for a procedure."""
        return Bench(_ClockedCamera(self.camera, self.clock), self.hotplate, CameraSettings(), simulated=True,
                     on_drop=self.drop, on_add_mass=self.add_mass, on_new_beaker=self.new_beaker,
                     description=f"simulated bench ({self.release.name}, {self.release.mass_g:.2f} g, "
                                 f"x{self.clock.speed:g} time)",
                     frame_bytes=3 * self.scene.width * self.scene.height)  # a JPEG is below its raw RGB

    # -- faults ------------------------------------------------------------------------------------------
    def camera_busy(self, n: int = 1) -> None:
        """The next ``n`` captures fail as a busy camera would."""
        self.camera.inject_busy(n)

    def corrupt_frames(self, n: int = 1) -> None:
        """The next ``n`` frames arrive truncated."""
        self.camera.inject_corrupt(n)

    def drop_hotplate_link(self, down_s: float = math.inf) -> None:
        """The hotplate's serial link goes dead for ``down_s`` wall seconds (default: until
        :meth:`restore_hotplate_link`)."""
        if self.emulator is not None:
            self.emulator.drop_link(down_s if math.isfinite(down_s) else 1e9)

    def restore_hotplate_link(self) -> None:
        """The hotplate's serial link answers again (ends :meth:`drop_hotplate_link` now)."""
        if self.emulator is not None:
            self.emulator.restore_link()

    def cool_bath(self, delta_c: float) -> None:
        """The water's temperature drops by ``delta_c`` C at once (cold water poured in, a draught); the
        plate's controller then heats it back."""
        if self.emulator is not None:
            self.emulator.disturb_water(-delta_c)

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
    t0 = snap.record.t0_unix_s
    last = snap.frames[-1].t_unix_s if snap.frames else (time.time() if t0 is None else t0)
    down_wall_s = max(time.time() - (folder / FRAMES_CSV).stat().st_mtime, 0.0)
    start = last + (down_wall_s * speed if math.isfinite(speed) else 0.0)
    return SteppedClock(start) if math.isinf(speed) else ScaledClock(speed, start_s=start)
