"""Image files to linear-light arrays: JPEG/PNG/TIFF through OpenCV, camera raw through rawpy.

8- and 16-bit JPEG/PNG/TIFF pixels are taken as sRGB-encoded (what cameras and converters write) and
linearised with the sRGB transfer curve before any photometry. Raw files are developed linearly: gamma 1,
no auto-brightening, unit white-balance multipliers, 16 bit. ``reduce`` = 2, 4 or 8 uses libjpeg's
DCT-domain downscaling for JPEG (``cv2.IMREAD_REDUCED_COLOR_n``: each output pixel is the mean of an
n x n block, decoded several times faster), area averaging for other formats and rawpy's half-size mode
(2x2 Bayer quads) for raw. Cell means barely change (docs/analysis.md, "What downscaled decoding costs").
"""
from __future__ import annotations

import functools
import io
from pathlib import Path

import cv2
import numpy as np

from analysis.errors import AnalysisError

RAW_SUFFIXES = frozenset({".nef", ".nrw", ".cr2", ".cr3", ".crw", ".dng", ".arw", ".orf", ".rw2", ".raf", ".pef",
                          ".srw", ".raw"})
IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"}) | RAW_SUFFIXES
REDUCE_FACTORS = (1, 2, 4, 8)
_REDUCED_FLAGS = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
                  8: cv2.IMREAD_REDUCED_COLOR_8}
_JPEG_EOI = b"\xff\xd9"


def check_reduce(reduce: int) -> int:
    """``reduce`` if it is one of 1, 2, 4, 8; else :class:`AnalysisError`."""
    if reduce not in REDUCE_FACTORS:
        raise AnalysisError(f"reduce={reduce!r} is not one of {REDUCE_FACTORS}")
    return reduce


@functools.lru_cache(maxsize=2)
def srgb_to_linear_lut(bits: int) -> np.ndarray:
    """Lookup table from ``bits``-bit sRGB codes to linear light in [0, 1]; (2**bits,) float32."""
    x = np.arange(2 ** bits, dtype=np.float64) / (2 ** bits - 1)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _read_bytes(source: str | Path | bytes) -> tuple[bytes, str]:
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source), "<bytes>"
    path = Path(source)
    try:
        return path.read_bytes(), str(path)
    except OSError as exc:
        raise AnalysisError(f"cannot read image {path}: {exc.strerror or exc}") from exc


def _decode_raw(data: bytes, name: str, reduce: int) -> np.ndarray:
    import rawpy  # heavy, and only needed for raw files

    try:
        with rawpy.imread(io.BytesIO(data)) as raw:
            rgb = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=False,
                                  use_auto_wb=False, user_wb=[1.0, 1.0, 1.0, 1.0], half_size=reduce >= 2)
    except (rawpy.LibRawError, ValueError) as exc:
        # rawpy's messages are bytes (b'Input/output error'); LibRaw reports a file cut short as an I/O error.
        detail = exc.args[0].decode(errors="replace") if exc.args and isinstance(exc.args[0], bytes) else str(exc)
        if isinstance(exc, rawpy.LibRawIOError):
            detail += " (the file is truncated or corrupt)"
        raise AnalysisError(f"cannot decode camera raw {name}: {detail}") from exc
    if reduce > 2:
        rgb = cv2.resize(rgb, None, fx=2 / reduce, fy=2 / reduce, interpolation=cv2.INTER_AREA)
    return rgb


def decode_encoded(source: str | Path | bytes, *, reduce: int = 1) -> tuple[np.ndarray, bool]:
    """Decode to integer codes without linearising (the fast path of :func:`analysis.read_cells`).

    Returns
    -------
    image : (H, W, 3) ndarray of uint8 or uint16, RGB
    linear : bool
        True for raw files (already linear), False for sRGB-encoded codes.

    Raises
    ------
    AnalysisError
        Unreadable, corrupt or truncated file.
    """
    check_reduce(reduce)
    data, name = _read_bytes(source)
    if not data:
        raise AnalysisError(f"image {name} is empty (0 bytes)")
    if isinstance(source, (str, Path)) and Path(source).suffix.lower() in RAW_SUFFIXES:
        return _decode_raw(data, name, reduce), True
    buf = np.frombuffer(data, np.uint8)
    is_jpeg = data[:2] == b"\xff\xd8"
    if is_jpeg and _JPEG_EOI not in data[-64:]:
        raise AnalysisError(f"JPEG {name} is truncated (no end-of-image marker); the file was cut short")
    if is_jpeg:
        image = cv2.imdecode(buf, _REDUCED_FLAGS[reduce])
    else:
        image = cv2.imdecode(buf, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR)
        if image is not None and reduce > 1:
            image = cv2.resize(image, None, fx=1 / reduce, fy=1 / reduce, interpolation=cv2.INTER_AREA)
    if image is None:
        if not isinstance(source, (str, Path)):
            try:
                return _decode_raw(data, name, reduce), True
            except AnalysisError:
                raise AnalysisError(f"cannot decode image {name}: neither JPEG/PNG/TIFF nor camera raw") from None
        raise AnalysisError(f"cannot decode image {name}: not a readable JPEG/PNG/TIFF (corrupt or wrong type)")
    if image.dtype not in (np.uint8, np.uint16):
        raise AnalysisError(f"image {name} has unsupported sample type {image.dtype} (need 8 or 16 bit)")
    return image[..., ::-1], False


def linearise(codes: np.ndarray, *, linear: bool = False) -> np.ndarray:
    """Integer codes to linear light in [0, 1], float32; sRGB curve unless ``linear``."""
    bits = 8 if codes.dtype == np.uint8 else 16
    if linear:
        return codes.astype(np.float32) / np.float32(2 ** bits - 1)
    return srgb_to_linear_lut(bits)[codes]


def decode_image(source: str | Path | bytes, *, reduce: int = 1) -> np.ndarray:
    """Decode an image file (or its bytes) to linear light.

    Parameters
    ----------
    source : path or bytes
        JPEG, PNG, TIFF or camera raw (raw is recognised by suffix, or by bytes no other decoder reads).
    reduce : {1, 2, 4, 8}
        Downscaling factor applied while decoding.

    Returns
    -------
    (H, W, 3) ndarray of float32, linear light in [0, 1], RGB

    Raises
    ------
    AnalysisError
        Unreadable, corrupt or truncated file, or a bad ``reduce``.
    """
    codes, linear = decode_encoded(source, reduce=reduce)
    return linearise(codes, linear=linear)
