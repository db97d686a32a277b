"""Devices: cameras, hotplates, and their emulators in `drivers.sim`."""
