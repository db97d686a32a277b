"""What a target spec names: a sample shape, a mesh file, a ``tau_mm,released_mm3`` CSV or an analytic family.

A target spec is one of: a sample shape name (`design.geometry.shapes.SAMPLE_SHAPES`), a mesh file
(.stl/.obj/.ply/.off/.3mf), a ``tau_mm,released_mm3`` CSV, or an analytic family
``zero-order[:final=F,duration=D]`` / ``accel:q=Q[,final=F,duration=D]`` with F the total release
as a fraction of the domain volume and D the release's end as a fraction of T (Fig. 7).
"""
from __future__ import annotations

from pathlib import Path

from design._validate import MESH_SUFFIXES
from design.errors import DesignError
from design.geometry.shapes import SAMPLE_SHAPES


def parse_analytic(spec: str) -> tuple[float, float, float] | None:
    """``(q, final, duration)`` of an analytic target spec, else None.

    Raises
    ------
    DesignError
        For an unknown parameter or a value that is not a number.
    """
    head, _, tail = spec.partition(":")
    if head not in ("zero-order", "accel"):
        return None
    params = {"q": 1.0, "final": 0.15, "duration": 0.2}
    for item in filter(None, tail.split(",")):
        key, _, value = item.partition("=")
        if key not in params:
            raise DesignError(f"unknown analytic target parameter {key!r} in {spec!r}; use q, final, duration")
        try:
            params[key] = float(value)
        except ValueError as exc:
            raise DesignError(f"bad value {value!r} for {key} in target {spec!r}") from exc
    if head == "zero-order":
        params["q"] = 1.0
    for key, ok, expected in (("q", params["q"] >= 0, "a number >= 0: the final over the initial release rate "
                                                     "(1 = zero-order, 0 = the rate falls to zero)"),
                              ("final", 0 < params["final"] <= 1, "in (0, 1]: the total release as a fraction of "
                                                                  "the domain volume"),
                              ("duration", 0 < params["duration"] <= 1, "in (0, 1]: when the release ends, as a "
                                                                        "fraction of the simulated time T")):
        if not ok:      # NaN fails every comparison: refused too
            raise DesignError(f"target {spec!r}: {key} = {params[key]:g}; expected {expected}")
    return params["q"], params["final"], params["duration"]


def is_shape_target(spec: str) -> bool:
    """Whether a target spec names a source shape (a sample shape or a mesh file), not a curve."""
    return spec in SAMPLE_SHAPES or Path(spec).suffix.lower() in MESH_SUFFIXES


def target_file(spec: str) -> str | None:
    """What file a target spec names: "mesh" (a mesh file), "csv" (a ``tau_mm,released_mm3`` curve) or None
    (a sample shape or an analytic family, which need no file)."""
    if spec in SAMPLE_SHAPES:
        return None
    if is_shape_target(spec):
        return "mesh"
    if parse_analytic(spec) is None and spec.lower().endswith(".csv"):
        return "csv"
    return None
