"""GPhotoCamera through the real python-gphoto2 + libgphoto2 stack and its virtual Nikon D750.

The virtual camera (VCAMERADIR) serves the one JPEG in its folder, re-reading the bytes at each
download with the size it saw at initialisation; the tests therefore feed frames of equal size into
that file before each capture. gphoto2 is imported only in the driver's worker process, which
inherits the environment set here.
"""
import os

import cv2
import numpy as np
import pytest

from drivers.camera import CameraError, CameraSettings, CaptureMissed, GPhotoCamera


def frames_of_equal_size(n, size=4000, seed=0):
    """n distinct JPEGs padded with a comment segment to exactly ``size`` bytes."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        ok, buf = cv2.imencode(".jpg", rng.integers(0, 255, (24, 32, 3)).astype(np.uint8))
        body = buf.tobytes()
        pad = size - len(body) - 4
        assert ok and 0 <= pad < 65533
        out.append(body[:2] + b"\xff\xfe" + (pad + 2).to_bytes(2, "big") + bytes(pad) + body[2:])
    return out


@pytest.fixture
def served(tmp_path, monkeypatch):
    folder = tmp_path / "served"
    folder.mkdir()
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("VCAMERADIR", str(folder))
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(home))
    path = folder / "frame.jpg"
    path.write_bytes(frames_of_equal_size(1, seed=99)[0])
    return path


def test_frames_come_back_in_order_and_byte_identical(served):
    frames = frames_of_equal_size(5)
    with GPhotoCamera(deadline_s=20) as camera:
        got = []
        for frame in frames:
            served.write_bytes(frame)
            got.append(camera.capture())
    assert [c.data for c in got] == frames
    assert len({c.file_name for c in got}) == 5
    times = [c.t_unix_s for c in got]
    assert times == sorted(times) and all(c.extra == {} for c in got)
    assert camera.name == "Nikon DSC D750"


def test_settings_the_camera_lacks_are_reported_not_fatal(served):
    with GPhotoCamera(deadline_s=20) as camera:
        outcome = camera.configure(CameraSettings())
        assert outcome["aperture"] == "set to f/22"
        assert outcome["capture_target"] == "set to Internal RAM"
        assert outcome["iso"] == "not exposed by this camera"
        assert outcome["image_format"] == "not exposed by this camera"
        assert outcome["shutter_speed"].startswith("'1/125' not offered (choices: ")
        assert camera.capture().data == served.read_bytes()


def test_store_full_is_recovered_by_reinitialising(served):
    # the virtual camera declares its store full at the 27th capture of a session
    with GPhotoCamera(deadline_s=20, retry_delay_s=0.0) as camera:
        first_pid = camera.worker_pid
        for _ in range(30):
            assert camera.capture().data == served.read_bytes()
        assert camera.worker_pid != first_pid and camera.missed == 0


def test_a_hung_capture_is_missed_and_the_run_goes_on(served):
    data = served.read_bytes()
    served.unlink()
    os.mkfifo(served)  # libgphoto2 blocks opening it: a capture that never returns
    with GPhotoCamera(deadline_s=2.0) as camera:
        hung_pid = camera.worker_pid
        with pytest.raises(CaptureMissed, match=r"did not finish within 2 s; camera reset, frame missed \(1 so far\)"):
            camera.capture()
        served.unlink()
        served.write_bytes(data)
        results = [camera.capture() for _ in range(3)]
        assert [r.data for r in results] == [data] * 3
        assert camera.missed == 1 and camera.resets == 1 and camera.worker_pid != hung_pid


def test_no_matching_camera_is_a_clear_error(served):
    with pytest.raises(CameraError, match=r"no camera found on USB \(Canon EOS; libgphoto2 error -105\): is it "
                                          r"switched on and not claimed by another program\?"):
        GPhotoCamera(model="Canon EOS", connect_deadline_s=20).connect()


def test_arguments_are_checked():
    with pytest.raises(ValueError, match="deadlines must be > 0 s"):
        GPhotoCamera(deadline_s=0)
