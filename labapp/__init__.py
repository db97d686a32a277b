"""The bench application: acquisition engine, run storage, `sfr` CLI and Qt GUI.

The only package that wires `design`, `analysis` and `drivers` together.
"""
