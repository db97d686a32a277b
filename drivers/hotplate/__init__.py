"""Stirring hotplates: the interface, the NAMUR command tables and the serial driver."""
from drivers.hotplate.base import Hotplate, HotplateError, HotplateReading
from drivers.hotplate.heidolph import HeidolphHotplate, HotplateConfig, NamurHotplate
from drivers.hotplate.protocol import HEIDOLPH_HEI_TEC, IKA_RCT, NO_PROBE_C, TABLES, ProtocolTable, Reading, Setpoint

__all__ = ["HEIDOLPH_HEI_TEC", "IKA_RCT", "NO_PROBE_C", "TABLES", "HeidolphHotplate", "Hotplate", "HotplateConfig",
           "HotplateError", "HotplateReading", "NamurHotplate", "ProtocolTable", "Reading", "Setpoint"]
