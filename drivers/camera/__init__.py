"""Cameras: the interface and its gphoto2, folder and simulated implementations."""
from drivers.camera.base import Camera, CameraError, CameraSettings, Capture, CaptureMissed
from drivers.camera.folder import FolderCamera
from drivers.camera.gphoto import GPhotoCamera, detect_cameras
from drivers.camera.simulated import SimulatedCamera

__all__ = ["Camera", "CameraError", "CameraSettings", "Capture", "CaptureMissed", "FolderCamera",
           "GPhotoCamera", "SimulatedCamera", "detect_cameras"]
