"""The one exception type of :mod:`analysis`."""
from __future__ import annotations


class AnalysisError(Exception):
    """An image, folder, manifest or calibration cannot be analysed; the message names it and says why."""
