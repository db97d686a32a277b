"""The barrier's relative speed in ``sfr calibrate-sim``: rows of coated prints, their coats, and the fit.

A set file row with a ``barrier_mesh`` (:mod:`labapp.records.simcalset`) is a coated print: the drug ``mesh`` inside
a clear barrier coat of uniform thickness c (the drug's box grown by c on every face, or a convex drug offset by
c). Such a print releases the uncoated drug's curve delayed by c / s (mm of drug; paper eq. 5 with the barrier's
slowness 1 / s, docs/materials.md), so its run says nothing new about the drug and everything about s: the
drug's calibration is fitted on the uncoated rows alone (:func:`split_coated`), and s on the coated ones with it
(:func:`barrier_block`, :func:`analysis.barrier_fit.fit_barrier_runs`), as the ``barrier`` block of ``simcal.json``
that ``sfr design --simcal SIMCAL --barrier-speed`` reads.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import AnalysisError, SimCal
from analysis.barrier_fit import CoatedRun, fit_barrier_runs
from labapp.records.curvefiles import CurveFileError, read_physical_curve
from labapp.records.fileio import sha256_file
from labapp.records.simcal import SimCalError
from labapp.records.simcalset import SetRow, row_inputs

log = logging.getLogger(__name__)

COAT_UNIFORMITY = 0.02
"""A coat is uniform when its thickness over the drug's surface varies by at most this fraction of its mean: s is
fitted as c / delay, so a coat this uneven biases s by up to as much (a box grown by c on every face is exact)."""
COAT_SAMPLES = 4000
"""Points sampled on the drug's surface (besides its vertices) to measure the coat."""
MIN_UNCOATED = 2
"""Uncoated rows a set with coated prints needs: the drug's calibration is fitted on them."""
METHOD = ("each coated run fitted for its own rate k_r, density and delay D against its drug's simulated release "
          "through the calibration (analysis.barrier_fit); s = mean of c / D; error = the runs' standard error (one "
          "run: the fit's own) and half the difference from speed_at_calibrated_rate (c k / (k_r D)), in quadrature")


@dataclass(frozen=True)
class CoatedRow:
    """A coated print's set row with its drug and barrier meshes and the coat's thickness, mm."""

    row: SetRow
    drug: object
    barrier: object
    coat_mm: float


def coat_thickness_mm(drug, barrier, where: str) -> float:
    """The thickness of a uniform barrier coat around a drug body, mm.

    The coat is measured from the drug's surface to the surface of the print (the union of both meshes: a barrier
    mesh may be the whole coated block or the coat's own solid with its inner faces on the drug), exactly (point to
    triangle).

    Parameters
    ----------
    drug, barrier : trimesh.Trimesh
        Watertight meshes, mm.
    where : str
        The set file and row, for messages.

    Raises
    ------
    SimCalError
        A barrier that is not watertight, does not cover the whole drug, or is not uniform to `COAT_UNIFORMITY`.
    """
    import trimesh

    from design.forward.reference import signed_distance

    if not barrier.is_watertight:
        raise SimCalError(f"{where}: the barrier mesh is not watertight; a coat is a closed solid around the drug")
    envelope = trimesh.boolean.union([drug, barrier], engine="manifold")     # the print: drug and barrier
    samples, _ = trimesh.sample.sample_surface(drug, COAT_SAMPLES, seed=0)
    distance = signed_distance(envelope, np.vstack([drug.vertices, samples]))   # > 0 inside the print
    if not np.all(distance > 1e-6 * float(np.max(drug.extents))):
        raise SimCalError(f"{where}: {np.count_nonzero(distance <= 0)} of {distance.size} points of the drug's surface "
                          "lie on the print's surface; a coated print's barrier covers the whole drug")
    mean = float(np.mean(distance))
    spread = float(np.max(distance) - np.min(distance))
    if not mean > 0 or spread > COAT_UNIFORMITY * mean:
        raise SimCalError(f"{where}: the coat is {np.min(distance):.3f} to {np.max(distance):.3f} mm thick; a calibration "
                          f"coat is uniform to {100 * COAT_UNIFORMITY:g} % (the drug's box grown by c on every face, or "
                          "a convex drug offset by c)")
    return mean


def split_coated(set_csv: Path, rows: list[SetRow]) -> tuple[list[SetRow], list[CoatedRow]]:
    """The set's uncoated rows (the drug's calibration) and its coated prints with their measured coats.

    Raises
    ------
    SimCalError
        A barrier mesh that cannot be read or is not a uniform coat (the row named), or coated rows with fewer than
        `MIN_UNCOATED` uncoated ones.
    """
    from design.errors import DesignError
    from design.files.meshio import load_mesh

    plain = [r for r in rows if r.barrier_mesh is None]
    if len(plain) == len(rows):
        return plain, []
    if len(plain) < MIN_UNCOATED:
        raise SimCalError(f"{set_csv}: {len(plain)} rows without a barrier_mesh; the drug is calibrated on at least "
                          f"{MIN_UNCOATED} uncoated prints, and the coated ones give the barrier's speed")
    coated, loaded = [], {}
    for row in rows:
        if row.barrier_mesh is None:
            continue
        where = f"{set_csv.name} row {row.row}"
        try:
            for path in (row.mesh, row.barrier_mesh):
                loaded.setdefault(path, load_mesh(path))
        except DesignError as exc:
            raise SimCalError(f"{where}: {exc}") from exc
        drug, barrier = loaded[row.mesh], loaded[row.barrier_mesh]
        coated.append(CoatedRow(row, drug, barrier, coat_thickness_mm(drug, barrier, where)))
    return plain, coated


def barrier_block(set_csv: Path, coated: list[CoatedRow], simulate: Callable[[SetRow], tuple], cal: SimCal,
                  physics: dict, bench=None, say: Callable[[float, str], None] = lambda f, m: None) -> dict:
    """The ``barrier`` block of ``simcal.json``: s and its standard error from the coated rows' runs.

    Parameters
    ----------
    set_csv : Path
    coated : list of CoatedRow
    simulate : callable
        ``simulate(row) -> (tau_mm, released_mm3, ...)``: the row's drug mesh released with the calibration's print
        physics.
    cal : analysis.SimCal
        The drug's calibration (its rate, density and wetting lag start each run's fit).
    physics : dict
        The print physics the calibration kept (an anisotropy other than 1 is warned about: the coat's faces along
        the build direction are then crossed at another time than the others, and the fit's delay is their mix).
    bench : analysis.BenchCalibration, optional
        The bench calibration run folders are analysed with (None: each run's own).

    Raises
    ------
    SimCalError
        An unreadable run, or a run the fit refuses (no release, no delay), with the row named.
    """
    runs, hashes = [], {}
    for k, c in enumerate(coated):
        where = f"{set_csv.name} row {c.row.row}"
        say(0.95, f"barrier: {where}, {c.row.run.name} ({c.coat_mm:.3f} mm coat) ...")
        try:
            curve = read_physical_curve(c.row.run, calibration=bench)
        except CurveFileError as exc:
            raise SimCalError(f"{where}: {exc}") from exc
        keep = curve.t_s >= 0
        tau, vol = simulate(c.row)[:2]
        runs.append(CoatedRun(curve.t_s[keep], curve.released_g[keep], c.coat_mm, tau, vol))
        hashes.update({str(p): sha256_file(p) for p in row_inputs(c.row)})
    try:
        fit = fit_barrier_runs(runs, cal.seconds_per_mm, cal.g_per_mm3, cal.lag_s)
    except AnalysisError as exc:
        raise SimCalError(f"{set_csv}: {exc}") from exc
    anisotropy = float(physics.get("anisotropy", 1.0))
    if anisotropy != 1.0:
        log.warning("%s: the calibration's anisotropy is %.3g: a coat's faces along the build direction are crossed "
                    "at another time than the others, and the barrier speed is their mix", set_csv, anisotropy)
    say(0.955, f"barrier speed {fit.speed:.4f} +- {fit.error:.4f} from {len(runs)} coated prints")
    return {"speed": fit.speed, "error": fit.error, "standard_error": fit.standard_error,
            "speed_at_calibrated_rate": fit.speed_at_calibrated_rate, "method": METHOD, "anisotropy": anisotropy,
            "runs": [{"run": str(c.row.run), "mesh": str(c.row.mesh), "barrier_mesh": str(c.row.barrier_mesh),
                      "coat_mm": c.coat_mm, "speed": s, "delay_mm": d, "rms_g": r}
                     for c, s, d, r in zip(coated, fit.per_run, fit.delays_mm, fit.rms_g)],
            "inputs_sha256": hashes}
