"""Small in-process devices for the labapp tests: a camera rendering the synthetic bench at a concentration
chosen by the test, and a hotplate with a one-line thermal model, both on the engine's clock."""
import numpy as np

from drivers.camera.base import CameraError, Capture, CaptureMissed
from drivers.hotplate.base import HotplateError, HotplateReading
from drivers.sim import BenchScene, render_jpeg

SCENE = BenchScene(width=480, height=320, intrusion_probability=0.0)


class RenderCamera:
    """Renders ``SCENE`` at ``conc_of_t(t_unix_s)`` g/kg; ``faults`` maps a capture number to an exception
    class or to ``"corrupt"`` (truncated JPEG bytes)."""

    def __init__(self, clock, conc_of_t, faults=None):
        self.clock, self.conc_of_t, self.faults = clock, conc_of_t, dict(faults or {})
        self.n, self.connected = 0, False
        self.rng = np.random.default_rng(1)

    def connect(self):
        self.connected = True

    def configure(self, settings):
        return {"aperture": "set", "iso": "not exposed by this camera"}

    def capture(self):
        self.n += 1
        fault = self.faults.get(self.n)
        if fault in (CameraError, CaptureMissed):
            raise fault(f"injected fault at capture {self.n}")
        t = self.clock.now()
        data = render_jpeg(SCENE, self.conc_of_t(t), t, self.rng)
        if fault == "corrupt":
            data = data[:200]
        return Capture(data, f"IMG_{self.n:04d}.JPG", t)

    def close(self):
        self.connected = False


class ModelHotplate:
    """Water temperature approaching the setpoint exponentially on the engine's clock; ``fail_reads`` makes
    that many reads raise (a dropped link)."""

    def __init__(self, clock, start_c=21.0, tau_s=300.0):
        self.clock, self.tau_s = clock, tau_s
        self.temp_c, self.t_last = start_c, clock.now()
        self.setpoint_c, self.speed_rpm, self.heating, self.stirring = 0.0, 0.0, False, False
        self.fail_reads = 0
        self.log = []

    def _advance(self):
        now = self.clock.now()
        if self.heating:
            self.temp_c += (self.setpoint_c - self.temp_c) * (1 - np.exp(-(now - self.t_last) / self.tau_s))
        self.t_last = now

    def connect(self):
        self.log.append("connect")

    def set_temperature(self, temp_c):
        self.setpoint_c = temp_c

    def set_speed(self, speed_rpm):
        self.speed_rpm = speed_rpm

    def start_heating(self):
        self._advance()
        self.heating = True

    def stop_heating(self):
        self.heating = False
        self.log.append("heating off")

    def start_stirring(self):
        self.stirring = True

    def stop_stirring(self):
        self.stirring = False

    def read(self):
        if self.fail_reads:
            self.fail_reads -= 1
            raise HotplateError("injected: link dropped on /dev/fake")
        self._advance()
        return HotplateReading(self.temp_c + 1.0, self.temp_c, self.speed_rpm if self.stirring else 0.0,
                               self.setpoint_c, self.speed_rpm, self.heating, self.stirring, self.clock.now())

    def close(self):
        self.heating = False
        self.log.append("close")
