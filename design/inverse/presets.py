"""Hyperparameter presets from the paper's Tables 1 and 2 (``--preset paper:NAME``).

Table 1 lists the settings of the Fig. 6 designs (targets from source shapes), Table 2 those of
the Fig. 7 designs (synthetic targets), each for the ICO space (w_b, w_f, r, beta) and the
extruded space (w_b, h, r, beta). The paper gives no separate NFC column; its NFC designs share
the ICO column without the ICO term, and so do these presets.

The paper's grids have 256 voxels per side (section 5.2). Weights, r and beta are used as
printed: w_f multiplies J_fab normalised to 1 at the start design (`design.fabrication.ico`), r is in voxels
of the grid actually used. The extrusion height h (voxels of the 256 grid) becomes a fraction of
the domain's longest side, ``h / 256``, so it keeps its physical meaning at any resolution.
"""
from __future__ import annotations

from design.errors import DesignError

PAPER_RESOLUTION = 256
"""Voxels per side of the paper's design grids (section 5.2)."""
PREFIX = "paper:"

# name: (ICO w_b, w_f, r, beta), (extruded w_b, h, r, beta)
_TABLE_1 = {
    "sphere": ((30, 50, 4, 3), (20, 160, 4, 3)),
    "pill": ((30, 120, 5, 3), (20, 70, 4, 3)),
    "spinner-top": ((20, 100, 4, 3), (50, 120, 4, 3)),
    "csg-1": ((30, 200, 5, 3), (20, 120, 4, 3)),
    "polyhedral-bow": ((20, 120, 5, 3), (20, 35, 4, 3)),
    "dodecahedron": ((20, 50, 4, 3), (50, 60, 4, 3)),
    "csg-2": ((50, 100, 4, 3), (50, 120, 4, 3)),
}
_TABLE_2 = {
    "design-1": ((40, 200, 9, 7), (50, 80, 9, 7)),
    "design-2": ((40, 200, 4, 3), (50, 90, 7, 5)),
    "design-3": ((20, 10, 4, 9), (40, 80, 4, 9)),
    "design-4": ((10, 10, 4, 9), (10, 200, 4, 9)),
    "design-5": ((20, 10, 4, 7), (20, 80, 4, 3)),
    "design-6": ((20, 10, 4, 7), (20, 100, 4, 7)),
}
PRESETS: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {**_TABLE_1, **_TABLE_2}
PRESET_NAMES: tuple[str, ...] = tuple(PREFIX + name for name in PRESETS)


def preset_values(preset: str, space: str) -> dict[str, float]:
    """`design.inverse.config.DesignConfig` fields set by a preset for one design space.

    Parameters
    ----------
    preset : str
        ``paper:NAME`` with NAME a row of Table 1 or 2 (e.g. ``paper:pill``, ``paper:design-4``).
    space : str
        "nfc", "extruded" or "ico".

    Returns
    -------
    dict
        ``w_binary``, ``radius_vox``, ``beta``, ``beta_final`` (= beta: the paper's fixed projection)
        and, for ico ``w_fab``, for extruded ``height_fraction``.

    Raises
    ------
    DesignError
        For an unknown preset or space.
    """
    name = preset[len(PREFIX):] if preset.startswith(PREFIX) else None
    if name not in PRESETS:
        raise DesignError(f"unknown preset {preset!r}; available: {', '.join(PRESET_NAMES)}")
    ico, extruded = PRESETS[name]
    if space in ("ico", "nfc"):
        w_b, w_f, r, beta = ico
        values = {"w_binary": float(w_b), "radius_vox": float(r), "beta": float(beta), "beta_final": float(beta)}
        if space == "ico":
            values["w_fab"] = float(w_f)
        return values
    if space == "extruded":
        w_b, h, r, beta = extruded
        return {"w_binary": float(w_b), "radius_vox": float(r), "beta": float(beta), "beta_final": float(beta),
                "height_fraction": h / PAPER_RESOLUTION}
    raise DesignError(f"presets cover the spaces nfc, extruded and ico, got {space!r}")
