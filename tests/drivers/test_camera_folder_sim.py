"""FolderCamera (files written by another program) and SimulatedCamera (rendered bench)."""
import cv2
import numpy as np
import pytest

from drivers.camera import Camera, CameraError, CameraSettings, CaptureMissed, FolderCamera, SimulatedCamera
from drivers.sim.bench_scene import BenchScene


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t

    def sleep(self, s):
        self.t += s


def test_folder_camera_ignores_old_files_and_waits_for_settled_new_ones(tmp_path):
    (tmp_path / "old.jpg").write_bytes(b"old")
    clock = FakeClock()
    writes = {0.4: ("a.jpg", b"12"), 0.8: ("a.jpg", b"1234"), 1.0: ("notes.txt", b"x")}

    def sleep(s):
        clock.sleep(s)
        for t, (name, data) in list(writes.items()):
            if clock.t >= t:
                (tmp_path / name).write_bytes(data)
                del writes[t]

    cam = FolderCamera(tmp_path, deadline_s=5, settle_s=0.5, poll_s=0.2, clock=clock, sleep=sleep)
    cam.connect()
    cap = cam.capture()
    assert (cap.file_name, cap.data) == ("a.jpg", b"1234")
    assert clock.t >= 1.3  # the size changed at 0.8 s and had to stay for 0.5 s
    with pytest.raises(CaptureMissed, match=r"no new image in .* within 5 s"):
        cam.capture()
    assert isinstance(cam, Camera)


def test_folder_camera_reports_settings_and_missing_folder(tmp_path):
    cam = FolderCamera(tmp_path / "nope")
    with pytest.raises(CameraError, match=r"camera folder .*nope does not exist"):
        cam.connect()
    assert set(cam.configure(CameraSettings())) == {"aperture", "shutter_speed", "iso", "image_format"}


def _decode(data):
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)


def test_simulated_camera_renders_the_curve_in_accelerated_time():
    clock = FakeClock()
    seen = []

    def conc(t_s):
        seen.append(t_s)
        return 0.0 if t_s < 100 else 2.0

    cam = SimulatedCamera(conc, BenchScene(), speed=50.0, seed=0, clock=clock, sleep=clock.sleep)
    assert cam.sim_time_s() == 0.0
    cam.connect()
    clear = cam.capture()
    clock.t = 4.0  # 200 simulated seconds
    assert cam.sim_time_s() == pytest.approx(200.0)
    dark = cam.capture()
    assert seen == [0.0, 200.0]
    a, b = _decode(clear.data), _decode(dark.data)
    assert a.shape == b.shape and a.mean() > b.mean()
    assert clear.file_name != dark.file_name and isinstance(cam, Camera)


def test_simulated_camera_faults():
    clock = FakeClock()
    cam = SimulatedCamera(lambda t: 0.5, speed=1.0, deadline_s=3.0, seed=1, clock=clock, sleep=clock.sleep)
    with pytest.raises(CameraError, match="not connected"):
        cam.capture()
    cam.connect()
    cam.inject_busy()
    with pytest.raises(CameraError, match="busy"):
        cam.capture()
    cam.inject_hang()
    with pytest.raises(CaptureMissed, match="within 3 s"):
        cam.capture()
    assert clock.t == 3.0
    cam.inject_corrupt()
    bad = cam.capture().data
    good = cam.capture().data
    assert good.endswith(b"\xff\xd9") and not bad.endswith(b"\xff\xd9")  # end-of-image marker lost
    assert _decode(good) is not None


def test_simulated_camera_arguments_are_checked():
    with pytest.raises(ValueError, match="speed and deadline_s must be > 0"):
        SimulatedCamera(lambda t: 0.0, speed=0)
