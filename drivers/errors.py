"""The one base exception of the `drivers` package."""
from __future__ import annotations


class DriverError(Exception):
    """A device could not be reached, configured or read; the message names the device and why."""
