"""A small, valid DNG synthesised with known linear truth (a helper for the raw-decode tests, not a test).

rawpy cannot write raw files and no camera file ships with the repository, so :func:`write_dng` builds
one: an uncompressed 16-bit Bayer RGGB CFA image in IFD0 with the DNG tags LibRaw needs
(DNGVersion, DNGBackwardVersion, UniqueCameraModel, CFARepeatPatternDim, CFAPattern, BlackLevel,
WhiteLevel, ColorMatrix1 + CalibrationIlluminant1, AsShotNeutral) and an EXIF sub-IFD holding
DateTimeOriginal and SubSecTimeOriginal. tifffile writes the TIFF; it cannot write an EXIF IFD, so
nor will it write tag 34665 (ExifIFD), so a placeholder tag 34664 (unassigned; it sorts in the same
place) is written, then renumbered to 34665 and pointed at an EXIF sub-IFD appended to the file.

The scene (see :func:`scene`) is two flat regions split at the centre column: the right half sees
the bare "panel" with per-channel signals ``PANEL`` (digital numbers above black), the left half the
same light times ``RATIO``, so every linear development keeps left/right == ``RATIO`` in every channel.

ColorMatrix1 is the inverse of LibRaw's sRGB-to-XYZ matrix, i.e. the camera's RGB *is* linear sRGB:
LibRaw's camera-to-sRGB matrix then comes out as the identity (to the 1e-4 rounding of the rationals),
so with unit white balance the developed value of channel c is ``(raw - BLACK) / (WHITE - BLACK)``.
AsShotNeutral is deliberately far from neutral so that applying the camera white balance would show.
"""
from __future__ import annotations

import datetime as _dt
import struct
from pathlib import Path

import numpy as np

HEIGHT, WIDTH = 64, 96  # px, even (whole 2x2 Bayer quads)
BLACK = 512  # DN
WHITE = 16383  # DN (a 14-bit sensor stored in 16-bit samples)
PANEL = {"R": 3000.0, "G": 5000.0, "B": 2000.0}  # DN above black in the right half
RATIO = 0.4  # left half / right half, every channel
AS_SHOT_NEUTRAL = (0.5, 1.0, 0.7)  # camera white balance a correct decode must ignore
CAPTURE_TIME = _dt.datetime(2024, 3, 5, 14, 7, 9, 250000)  # DateTimeOriginal 2024:03:05 14:07:09 + SubSec "25"

# XYZ (D65) -> linear sRGB: the inverse of LibRaw's xyz_rgb, so camera RGB = linear sRGB.
_XYZ_TO_SRGB = ((3.2404542, -1.5371385, -0.4985314),
                (-0.9692660, 1.8760108, 0.0415560),
                (0.0556434, -0.2040259, 1.0572252))
_CFA_COLOURS = ("R", "G", "G", "B")  # RGGB: (0,0) R, (0,1) G, (1,0) G, (1,1) B
_EXIF_IFD = 34665
_PLACEHOLDER = 34664  # unassigned tag code just below ExifIFD, which tifffile refuses to write


def scene(gain: float = 1.0) -> np.ndarray:
    """Linear signal above black per CFA site, DN: (HEIGHT, WIDTH) float64, left half = RATIO * right half."""
    signal = np.empty((HEIGHT, WIDTH))
    for i, colour in enumerate(_CFA_COLOURS):
        signal[i // 2::2, i % 2::2] = PANEL[colour]
    signal[:, : WIDTH // 2] *= RATIO
    return gain * signal


def expected_linear(gain: float = 1.0) -> dict[str, np.ndarray]:
    """What a linear, unit-white-balance, un-brightened decode must give: {"left"/"right": (3,) RGB in [0, 1]}."""
    right = gain * np.array([PANEL["R"], PANEL["G"], PANEL["B"]]) / (WHITE - BLACK)
    return {"left": RATIO * right, "right": right}


def _rationals(values, den: int = 10000) -> list[int]:
    out: list[int] = []
    for v in values:
        out += [int(round(v * den)), den]
    return out


def _exif_ifd(offset: int, when: _dt.datetime) -> bytes:
    """Little-endian EXIF IFD placed at file ``offset``: ExifVersion, DateTimeOriginal, SubSecTimeOriginal."""
    stamp = when.strftime("%Y:%m:%d %H:%M:%S").encode() + b"\x00"  # 20 bytes
    subsec = f"{when.microsecond // 10000:02d}".encode() + b"\x00"  # 3 bytes, inline
    n = 3
    data_at = offset + 2 + 12 * n + 4
    entries = [
        struct.pack("<HHI4s", 36864, 7, 4, b"0230"),  # ExifVersion, UNDEFINED
        struct.pack("<HHII", 36867, 2, len(stamp), data_at),  # DateTimeOriginal, ASCII
        struct.pack("<HHI4s", 37521, 2, len(subsec), subsec.ljust(4, b"\x00")),  # SubSecTimeOriginal
    ]
    return struct.pack("<H", n) + b"".join(entries) + struct.pack("<I", 0) + stamp


def dng_bytes(gain: float = 1.0, *, capture_time: _dt.datetime | None = CAPTURE_TIME) -> bytes:
    """The DNG of :func:`scene` (``gain`` times the signal above black), as bytes."""
    import io

    import tifffile

    cfa = np.round(BLACK + scene(gain)).astype(np.uint16)
    if cfa.max() >= WHITE:
        raise ValueError(f"gain={gain} clips the scene at the white level {WHITE} DN")
    extratags = [
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, "Synthetic RGGB Test Camera", True),  # UniqueCameraModel
        (271, "s", 0, "Synthetic", True),  # Make
        (272, "s", 0, "RGGB Test Camera", True),  # Model
        (274, "H", 1, 1, True),  # Orientation: top-left
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, (0, 1, 1, 2), True),  # CFAPattern: R G / G B
        (50710, "B", 3, (0, 1, 2), True),  # CFAPlaneColor
        (50711, "H", 1, 1, True),  # CFALayout: rectangular
        (50714, "I", 1, BLACK, True),  # BlackLevel
        (50717, "I", 1, WHITE, True),  # WhiteLevel
        (50721, 10, 9, _rationals([v for row in _XYZ_TO_SRGB for v in row]), True),  # ColorMatrix1, SRATIONAL
        (50778, "H", 1, 21, True),  # CalibrationIlluminant1: D65
        (50728, 5, 3, _rationals(AS_SHOT_NEUTRAL), True),  # AsShotNeutral, RATIONAL
    ]
    if capture_time is not None:
        extratags.append((_PLACEHOLDER, "I", 1, 0, True))  # becomes ExifIFD below
        extratags.append((306, "s", 0, capture_time.strftime("%Y:%m:%d %H:%M:%S"), True))  # DateTime
    buf = io.BytesIO()
    tifffile.imwrite(buf, cfa, photometric=32803, subfiletype=0, metadata=None, software=False,
                     byteorder="<", extratags=extratags)
    data = bytearray(buf.getvalue())
    if capture_time is not None:
        buf.seek(0)
        with tifffile.TiffFile(buf) as tif:
            pointer_at = tif.pages[0].tags[_PLACEHOLDER].valueoffset  # classic TIFF: entry starts 8 bytes before
        offset = len(data) + (len(data) % 2)  # IFDs start on a word boundary
        data += b"\x00" * (offset - len(data)) + _exif_ifd(offset, capture_time)
        data[pointer_at - 8:pointer_at + 4] = struct.pack("<HHII", _EXIF_IFD, 4, 1, offset)  # LONG offset
    return bytes(data)


def write_dng(path: str | Path, gain: float = 1.0, *, capture_time: _dt.datetime | None = CAPTURE_TIME) -> Path:
    """Write :func:`dng_bytes` to ``path`` (suffix ``.dng``) and return the path."""
    path = Path(path)
    path.write_bytes(dng_bytes(gain, capture_time=capture_time))
    return path
