"""Capture time of an image file from its EXIF tags (Pillow for JPEG/TIFF, exifread for camera raw)."""
from __future__ import annotations

import datetime as _dt
import logging
from pathlib import Path

from analysis.decode import RAW_SUFFIXES

log = logging.getLogger(__name__)

_EXIF_IFD = 0x8769
_DATETIME_ORIGINAL = 36867
_SUBSEC_ORIGINAL = 37521
_DATETIME = 306


def _parse(stamp: str | bytes | None, subsec: str | bytes | None) -> _dt.datetime | None:
    if not stamp:
        return None
    text = (stamp.decode(errors="replace") if isinstance(stamp, bytes) else str(stamp)).strip().rstrip("\x00")
    try:
        if len(text) != 19:  # strptime would take a cut-short "2024:03:05 14:07:0" as 14:07:00
            raise ValueError(text)
        when = _dt.datetime.strptime(text, "%Y:%m:%d %H:%M:%S")
    except ValueError:
        log.debug("unparseable EXIF time %r", text)
        return None
    frac = (subsec.decode(errors="replace") if isinstance(subsec, bytes) else str(subsec or "")).strip().rstrip("\x00")
    if frac.isdigit():
        when += _dt.timedelta(seconds=int(frac) / 10 ** len(frac))
    return when


def _pillow_time(path: Path) -> _dt.datetime | None:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as img:
            exif = img.getexif()
    except (OSError, UnidentifiedImageError):
        return None
    sub = exif.get_ifd(_EXIF_IFD)
    return _parse(sub.get(_DATETIME_ORIGINAL) or exif.get(_DATETIME), sub.get(_SUBSEC_ORIGINAL))


def _exifread_time(path: Path) -> _dt.datetime | None:
    import exifread

    try:
        with open(path, "rb") as fh:
            tags = exifread.process_file(fh, details=False, stop_tag="EXIF SubSecTimeOriginal")
    except Exception as exc:  # exifread raises IndexError, struct.error, ... on cut-short files
        log.debug("cannot read EXIF of %s: %r", path, exc)
        return None
    stamp = tags.get("EXIF DateTimeOriginal") or tags.get("Image DateTime")
    sub = tags.get("EXIF SubSecTimeOriginal")
    return _parse(None if stamp is None else str(stamp), None if sub is None else str(sub))


def capture_time(path: str | Path) -> _dt.datetime | None:
    """When the camera took the picture (EXIF DateTimeOriginal + SubSecTimeOriginal), or None.

    Parameters
    ----------
    path : str or Path
        JPEG/TIFF/PNG (read with Pillow) or camera raw (read with exifread).

    Returns
    -------
    datetime.datetime or None
        Naive camera-clock time; None when the file has no usable time tag.
    """
    path = Path(path)
    if path.suffix.lower() in RAW_SUFFIXES:
        return _exifread_time(path)
    return _pillow_time(path)
