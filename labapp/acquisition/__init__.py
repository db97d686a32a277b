"""Acquisition: the Qt-free engine, its clocks and events, the procedures it walks (runs, calibration
series), the bench's devices and the simulated bench."""
