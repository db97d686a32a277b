"""Thermal and stirring model of a hotplate heating a beaker of water (the emulator's physics).

Two first-order nodes: the plate approaches its target with time constant ``tau_plate_s``; the water
approaches the plate with ``tau_water_s`` and loses heat to the room with ``tau_loss_s``. With the
external probe in the water the plate's controller drives the plate above the setpoint in proportion
to the water's shortfall (proportional plus integral, so the water settles on the setpoint); without a
probe the plate itself is regulated. The stirrer ramps to its setpoint at ``ramp_rpm_per_s``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class ThermalParams:
    """Constants of the model; times in simulated seconds, temperatures in degrees C."""

    ambient_c: float = 21.0
    tau_plate_s: float = 60.0
    tau_water_s: float = 240.0
    tau_loss_s: float = 3600.0
    plate_max_c: float = 320.0
    gain: float = 0.8
    integral_per_s: float = 0.0005
    ramp_rpm_per_s: float = 100.0

    def __post_init__(self) -> None:
        for name in ("tau_plate_s", "tau_water_s", "tau_loss_s", "ramp_rpm_per_s"):
            if getattr(self, name) <= 0:
                raise ValueError(f"ThermalParams.{name} must be > 0, got {getattr(self, name)!r}")
        if not self.ambient_c < self.plate_max_c:
            raise ValueError(f"ThermalParams: ambient_c {self.ambient_c} must be below plate_max_c {self.plate_max_c}")


@dataclass(frozen=True)
class PlateState:
    """The plate as a user would see it: setpoints, switches and the measured values."""

    setpoint_c: float = 0.0
    setpoint_rpm: float = 0.0
    heating: bool = False
    stirring: bool = False
    plate_c: float = 21.0
    water_c: float = 21.0
    speed_rpm: float = 0.0
    probe_connected: bool = True
    integral_c: float = 0.0


def step(state: PlateState, dt_s: float, params: ThermalParams) -> PlateState:
    """Advance the model by ``dt_s`` simulated seconds (sub-stepped for stability).

    Parameters
    ----------
    state : PlateState
        State at the start of the step.
    dt_s : float
        Simulated seconds, >= 0.
    params : ThermalParams
        Model constants.

    Returns
    -------
    PlateState
        State at the end of the step.
    """
    if dt_s < 0:
        raise ValueError(f"dt_s must be >= 0, got {dt_s}")
    h_max = 0.2 * min(params.tau_plate_s, params.tau_water_s)
    n = max(1, int(dt_s / h_max) + 1)
    h = dt_s / n
    plate, water, integral = state.plate_c, state.water_c, state.integral_c
    for _ in range(n):
        if state.heating and state.probe_connected:
            error = state.setpoint_c - water
            integral = min(max(integral + params.integral_per_s * error * h, -50.0), 50.0)
            target = state.setpoint_c + params.gain * error + integral
        elif state.heating:
            target = state.setpoint_c
        else:
            target = params.ambient_c
        target = min(max(target, params.ambient_c), params.plate_max_c)
        if not state.heating and plate <= target:
            target = plate  # an idle plate does not heat itself; it only cools towards the room
        plate += (target - plate) * h / params.tau_plate_s
        water += ((plate - water) / params.tau_water_s - (water - params.ambient_c) / params.tau_loss_s) * h
    speed_target = state.setpoint_rpm if state.stirring else 0.0
    dv = params.ramp_rpm_per_s * dt_s
    speed = state.speed_rpm + max(-dv, min(dv, speed_target - state.speed_rpm))
    return replace(state, plate_c=plate, water_c=water, speed_rpm=speed, integral_c=integral)
