"""`SimulatedCamera`: bench frames rendered from any concentration curve, in accelerated time."""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

from drivers.camera.base import CameraError, CameraSettings, Capture, CaptureMissed
from drivers.sim.bench_scene import BenchScene, render_jpeg


class SimulatedCamera:
    """A camera looking at the synthetic bench (`drivers.sim.bench_scene`).

    Simulated time runs ``speed`` times faster than ``clock`` from `connect`; `sim_time_s` reads it, so a
    bench app can drive a whole run faster than real time. Faults for the app's own tests: `inject_busy`,
    `inject_hang`, `inject_corrupt` (each affects the next ``n`` captures).

    Parameters
    ----------
    conc_of_t : callable
        Concentration in g/kg as a function of simulated seconds since `connect`.
    scene : BenchScene
        The bench to render.
    speed : float
        Simulated seconds per real second, > 0.
    deadline_s : float
        Real seconds a hung capture blocks before `CaptureMissed` is raised.
    seed : int, optional
        Seed of the image noise and of corrupted bytes.
    clock, sleep : callable
        Real-time clock (monotonic, s) and sleep, injectable for tests.
    quality : int
        JPEG quality, 1..100.
    """

    def __init__(self, conc_of_t: Callable[[float], float], scene: BenchScene = BenchScene(), *,
                 speed: float = 1.0, deadline_s: float = 30.0, seed: int | None = None,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 quality: int = 92) -> None:
        if speed <= 0 or deadline_s <= 0:
            raise ValueError(f"speed and deadline_s must be > 0, got {speed!r}, {deadline_s!r}")
        self.conc_of_t = conc_of_t
        self.scene = scene
        self.speed = float(speed)
        self.deadline_s = deadline_s
        self.quality = quality
        self._rng = np.random.default_rng(seed)
        self._clock, self._sleep = clock, sleep
        self._t0: float | None = None
        self._count = 0
        self._busy = self._hang = self._corrupt = 0

    def sim_time_s(self) -> float:
        """Simulated seconds since `connect` (0 before it)."""
        return 0.0 if self._t0 is None else (self._clock() - self._t0) * self.speed

    def connect(self) -> None:
        """Start the simulated clock (a second call keeps it running)."""
        if self._t0 is None:
            self._t0 = self._clock()

    def configure(self, settings: CameraSettings) -> dict[str, str]:
        """Accept every setting: the renderer has one fixed exposure."""
        return {key: f"set to {value} (simulated)" for key, value in vars(settings).items() if value is not None}

    def capture(self) -> Capture:
        """Render the bench at the current simulated time.

        Raises
        ------
        CameraError
            An injected busy fault.
        CaptureMissed
            An injected hang (after blocking ``deadline_s`` real seconds).
        """
        if self._t0 is None:
            raise CameraError("simulated camera is not connected")
        if self._busy:
            self._busy -= 1
            raise CameraError("simulated camera busy (libgphoto2 error -110)")
        if self._hang:
            self._hang -= 1
            self._sleep(self.deadline_s)
            raise CaptureMissed(f"simulated capture did not finish within {self.deadline_s:g} s")
        t_s = self.sim_time_s()
        conc = float(self.conc_of_t(t_s))
        data = render_jpeg(self.scene, conc, t_s, self._rng, quality=self.quality)
        if self._corrupt:
            self._corrupt -= 1
            cut = len(data) // 2
            data = data[:cut] + self._rng.integers(0, 256, size=64, dtype=np.uint8).tobytes()
        self._count += 1
        return Capture(data=data, file_name=f"SIM_{self._count:05d}.JPG", t_unix_s=time.time())

    def close(self) -> None:
        self._t0 = None

    def inject_busy(self, n: int = 1) -> None:
        """Fault: the next ``n`` captures raise CameraError('busy')."""
        self._busy += n

    def inject_hang(self, n: int = 1) -> None:
        """Fault: the next ``n`` captures block ``deadline_s`` and raise CaptureMissed."""
        self._hang += n

    def inject_corrupt(self, n: int = 1) -> None:
        """Fault: the next ``n`` captures return a truncated JPEG with random bytes at the end."""
        self._corrupt += n
