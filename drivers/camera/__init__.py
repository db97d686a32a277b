"""Cameras: the interface and its gphoto2, folder and simulated implementations."""
from drivers.camera.base import Camera, CameraError, CameraSettings, Capture, CaptureMissed
from drivers.camera.gphoto import GPhotoCamera, detect_cameras

__all__ = ["Camera", "CameraError", "CameraSettings", "Capture", "CaptureMissed", "GPhotoCamera",
           "detect_cameras"]
