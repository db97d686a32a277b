"""``rounds.npz``: where a design run's defect-correction rounds stand (`design.inverse.defect.RoundState`).

Written atomically (a temporary file renamed over the old one) each time a round begins and once the last is
judged, so a resume reads either state; `design.inverse.defect.optimise_physical` reads it only when resuming.
The arrays are the `RoundState` fields and ``format`` (`ROUNDS_FORMAT`); a file without ``step``,
``best_grid_mm3`` and ``best_print_mm3`` (written before the rounds recorded them) reads as step 1 with the best
design's curves not recorded, which is how such a run continued.
"""
from __future__ import annotations

import os
import zipfile
from dataclasses import MISSING, fields
from pathlib import Path

import numpy as np

from design.errors import DesignError
from design.inverse.defect import RoundState

ROUNDS = "rounds.npz"
ROUNDS_FORMAT = 1
"""The layout of ``rounds.npz`` this version writes."""
_SCALARS = {"round": int, "start": int, "end": int, "best_fit": float, "best_pieces": int, "status": str,
            "step": float}
_OPTIONAL = {f.name for f in fields(RoundState) if f.default is not MISSING or f.default_factory is not MISSING}
"""The fields a file may lack (their `RoundState` defaults)."""


class RoundFile:
    """A run folder's ``rounds.npz``: the `design.inverse.defect.RoundStore` of `design.files.rundir.run_design`."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)

    def load(self) -> RoundState | None:
        """The stored state, None without a file.

        Raises
        ------
        DesignError
            When the file cannot be read as a round state, or its format is newer than this version reads.
        """
        if not self.path.exists():
            return None
        try:
            with np.load(self.path, allow_pickle=False) as data:
                stored = {name: data[name] for name in data.files}
            layout = int(stored.get("format", 0))
            if layout != ROUNDS_FORMAT:
                raise DesignError(f"{self.path}: format {layout} is not the layout this version reads "
                                  f"({ROUNDS_FORMAT})")
            values = {}
            for f in fields(RoundState):
                if f.name not in stored and f.name in _OPTIONAL:
                    continue
                cast = _SCALARS.get(f.name)
                values[f.name] = cast(stored[f.name][()]) if cast else np.asarray(stored[f.name], float)
        except DesignError:
            raise
        except (OSError, EOFError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as exc:
            raise DesignError(f"{self.path}: not a readable round state ({type(exc).__name__}: {exc}); "
                              "restore it or start a new run") from exc
        return RoundState(**values)

    def save(self, state: RoundState) -> None:
        """Write ``state`` atomically."""
        tmp = self.path.with_name(self.path.name + ".tmp.npz")
        arrays = {f.name: np.asarray(getattr(state, f.name)) for f in fields(RoundState)}
        with open(tmp, "wb") as handle:
            np.savez(handle, format=np.array(ROUNDS_FORMAT), **arrays)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, self.path)
