"""The forward-model evaluation of paper section 5.1 (Fig. 8): measured vs forward model vs Monte Carlo.

:func:`evaluate_models` takes a simulation calibration set (``run,mesh,object_mass_g``, as for
``sfr calibrate-sim``) and, for every object,

- the forward model's leave-one-out prediction: :func:`labapp.jobs.calibrate_sim.calibrate_sim` fits the section 4.3
  calibration without the object and predicts it from its mesh and weighed mass;
- the Monte Carlo model's leave-one-out prediction: (A, E_a) tuned on the other objects by the 16-point
  grid search (:func:`design.montecarlo.tuning.tune_mc`), the object simulated with them, its released fraction
  times its weighed mass;

and scores both against the measured curve with f2 (measured as the reference, rules of
:func:`analysis.similarity`) and the RMS error in percent of the weighed mass. It writes
``evaluation.json``, ``evaluation.csv``, ``evaluation.md`` (the table), ``evaluation.png`` (the picture),
the forward calibration in ``simcal/`` and the Monte Carlo calibration tuned on all objects in ``mc.json``.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.profile import ReleaseProfile, similarity
from design.errors import DesignError
from design.files.meshio import load_mesh
from design.files.pipeline import mesh_grid
from design.geometry.voxelize import DEFAULT_RESOLUTION
from design.montecarlo.erosion import DEFAULT_SEEDS
from design.montecarlo.tuning import DEFAULT_EA_J_PER_MOL, tune_mc, unit_runs
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.jobs.simulate_mc import calibration_doc
from labapp.records.fileio import atomic_write
from labapp.records.outpaths import FolderKind, check_out
from labapp.records.simcal import SimCalError
from labapp.records.simcalset import read_set

MODEL_NAMES = ("forward", "mc")
"""The two predictions of each object: the forward model (leave-one-out) and the Monte Carlo model."""
Progress = Callable[[float, str], None]


@dataclass(frozen=True, eq=False)
class ObjectEvaluation:
    """One object of the set: its measured curve, both predictions and their scores.

    Attributes
    ----------
    name : str
    mass_g : float
        Weighed mass, g.
    t_s : (N,) ndarray of float, s
    measured_g, forward_g, mc_g, mc_std_g : (N,) ndarray of float, g
        Measured release, the two leave-one-out predictions, and the Monte Carlo spread over seeds.
    f2 : dict of str to float or None
        Per model, f2 with the measured curve as the reference (None when the rules leave too few points).
    rms_pct : dict of str to float
        Per model, RMS(predicted - measured) in percent of the weighed mass.
    """

    name: str
    mass_g: float
    t_s: np.ndarray
    measured_g: np.ndarray
    forward_g: np.ndarray
    mc_g: np.ndarray
    mc_std_g: np.ndarray
    f2: dict
    rms_pct: dict


@dataclass(frozen=True, eq=False)
class Evaluation:
    """What :func:`evaluate_models` made."""

    objects: tuple[ObjectEvaluation, ...]
    doc: dict
    out: Path


def _score(t_s: np.ndarray, measured_g: np.ndarray, predicted_g: np.ndarray, mass_g: float, name: str):
    ref = ReleaseProfile(t_s, measured_g, total=mass_g, label=f"{name} measured")
    test = ReleaseProfile(t_s, np.maximum.accumulate(predicted_g), total=mass_g, label=f"{name} predicted")
    f2 = similarity(ref, test).f2
    rms = 100.0 * float(np.sqrt(np.mean((predicted_g - measured_g) ** 2))) / mass_g
    return f2, rms


def evaluate_models(set_csv: str | Path, bench_calibration: str | Path | None, out_dir: str | Path, *,
                    resolution: int | None = None, seeds: int = DEFAULT_SEEDS,
                    ea_values: tuple[float, ...] = DEFAULT_EA_J_PER_MOL,
                    progress: Progress | None = None) -> Evaluation:
    """Evaluate the forward model against the Monte Carlo baseline on a calibration set (Fig. 8).

    Parameters
    ----------
    set_csv : str or Path
        ``run,mesh,object_mass_g`` (see :func:`labapp.records.simcalset.read_set`); at least 3 objects for a
        meaningful leave-one-out.
    bench_calibration : str or Path or None
        Bench calibration for run folders (None: each run's own ``calibration.json``).
    out_dir : str or Path
        A new or empty folder.
    resolution : int, optional
        Voxels along each mesh's longest side, for both models (default: ``sfr calibrate-sim``'s).
    seeds : int
        Monte Carlo runs averaged per object and E_a.
    ea_values : tuple of float
        Activation energies of the Monte Carlo grid, J/mol (4 values x 4 A values = 16 combinations).
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    Evaluation
    """
    say = progress or (lambda fraction, message: None)
    set_csv, out_dir = Path(set_csv), Path(out_dir)
    resolution = DEFAULT_RESOLUTION if resolution is None else int(resolution)
    rows = read_set(set_csv)
    coated = [r.row for r in rows if r.barrier_mesh is not None]
    if coated:
        raise SimCalError(f"{set_csv}: rows {', '.join(map(str, coated))} name a barrier_mesh; an evaluation compares "
                          "one-material predictions (calibrate the barrier with sfr calibrate-sim)")
    if len(rows) < 3:
        raise SimCalError(f"{set_csv}: {len(rows)} objects; a leave-one-out evaluation needs at least 3")
    out_dir = check_out(out_dir, FolderKind.EVALUATION, [set_csv, bench_calibration] + [p for r in rows for p in (r.run, r.mesh)],
                        replace=False)
    out_dir.mkdir(parents=True, exist_ok=True)
    say(0.0, "forward model: simulation calibration and its leave-one-out predictions ...")
    forward = calibrate_sim(set_csv, bench_calibration, out_dir / "simcal", resolution=resolution,
                            progress=lambda f, m: say(0.4 * f, f"   {m}"))
    shapes = forward.doc["shapes"]
    objects = []
    for row in rows:
        try:
            objects.append(mesh_grid(load_mesh(row.mesh), resolution=resolution))
        except DesignError as exc:
            raise SimCalError(f"{row.mesh}: {exc}") from exc
    masses = [float(s["object_mass_g"]) for s in shapes]
    measured = [(s.t_s, s.measured_g / m) for s, m in zip(forward.loo, masses)]
    say(0.4, f"Monte Carlo: {len(ea_values)} activation energies x {len(rows)} objects x {seeds} seeds ...")
    runs = unit_runs(objects, ea_values=ea_values, seeds=seeds,
                     progress=lambda d, n: say(0.4 + 0.5 * d / n, f"   Monte Carlo run {d}/{n}"))
    results, tunings = [], []
    for k, (loo, row, mass) in enumerate(zip(forward.loo, rows, masses)):
        others = [i for i in range(len(rows)) if i != k]
        tuning = tune_mc(runs, measured, subset=others)
        tunings.append(tuning)
        p = tuning.params
        mean, std = runs.fraction(p.ea_j_per_mol, k, p.a_per_s, loo.t_s)
        mc_g, mc_std_g = mean * mass, std * mass
        name = f"{row.mesh.stem} ({row.run.name})"
        scores = {m: _score(loo.t_s, loo.measured_g, pred, mass, name)
                  for m, pred in (("forward", loo.predicted_g), ("mc", mc_g))}
        results.append(ObjectEvaluation(name, mass, loo.t_s, loo.measured_g, loo.predicted_g, mc_g, mc_std_g,
                                        {m: s[0] for m, s in scores.items()}, {m: s[1] for m, s in scores.items()}))
    say(0.92, "Monte Carlo calibration on all objects ...")
    full = tune_mc(runs, measured)
    volumes = [float((rho >= 0.5).sum()) * dx ** 3 * 2 ** sum(mirror) for rho, dx, mirror in objects]
    g_per_mm3 = float(sum(masses) / sum(volumes))
    mc_doc = calibration_doc(full, g_per_mm3, float(forward.doc["water_g"]), resolution,
                             [str(r.mesh) for r in rows])
    atomic_write(out_dir / "mc.json", (json.dumps(mc_doc, indent=2) + "\n").encode())
    doc = _document(results, tunings, forward.doc, mc_doc, set_csv, resolution, seeds)
    atomic_write(out_dir / "evaluation.json", (json.dumps(doc, indent=2) + "\n").encode())
    atomic_write(out_dir / "evaluation.csv", _csv(results).encode())
    atomic_write(out_dir / "evaluation.md", (markdown_table(doc) + "\n").encode())
    plot_evaluation(results, out_dir / "evaluation.png")
    say(1.0, f"wrote {out_dir}")
    return Evaluation(tuple(results), doc, out_dir)


def _mean(values) -> float | None:
    values = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(values)) if values else None


def _document(results, tunings, simcal_doc: dict, mc_doc: dict, set_csv: Path, resolution: int, seeds: int) -> dict:
    rows = []
    for r, t in zip(results, tunings):
        rows.append({"object": r.name, "mass_g": r.mass_g, "f2_forward": r.f2["forward"], "f2_mc": r.f2["mc"],
                     "rms_pct_forward": r.rms_pct["forward"], "rms_pct_mc": r.rms_pct["mc"],
                     "mc_a_per_s": t.params.a_per_s, "mc_ea_j_per_mol": t.params.ea_j_per_mol,
                     "mc_spread_max_pct": 100.0 * float(r.mc_std_g.max()) / r.mass_g})
    return {"set": str(set_csv), "resolution": resolution, "seeds": seeds, "objects": rows,
            "mean": {"f2_forward": _mean(x["f2_forward"] for x in rows), "f2_mc": _mean(x["f2_mc"] for x in rows),
                     "rms_pct_forward": _mean(x["rms_pct_forward"] for x in rows),
                     "rms_pct_mc": _mean(x["rms_pct_mc"] for x in rows)},
            "forward_calibration": {"model": simcal_doc["model"], "seconds_per_mm": simcal_doc["seconds_per_mm"],
                                    "density_g_per_cm3": simcal_doc["density_g_per_cm3"]},
            "mc_calibration": {k: mc_doc[k] for k in ("a_per_s", "ea_j_per_mol", "temp_k", "dx_mm", "rms", "grid")}}


def _csv(results) -> str:
    lines = ["object,mass_g,f2_forward,f2_mc,rms_pct_forward,rms_pct_mc"]
    fmt = (lambda v: "" if v is None else f"{v:.3f}")
    for r in results:
        lines.append(f"{r.name},{r.mass_g:.4f},{fmt(r.f2['forward'])},{fmt(r.f2['mc'])},"
                     f"{r.rms_pct['forward']:.3f},{r.rms_pct['mc']:.3f}")
    return "\n".join(lines) + "\n"


def markdown_table(doc: dict) -> str:
    """The evaluation table (f2 and RMS per object and model, then the means) in Markdown."""
    fmt = (lambda v, d=1: "n/a" if v is None else f"{v:.{d}f}")
    lines = ["| object | mass (g) | f2 forward (LOO) | f2 Monte Carlo (LOO) | RMS forward (% mass) | RMS Monte Carlo (% mass) |",
             "|---|---:|---:|---:|---:|---:|"]
    for x in doc["objects"]:
        lines.append(f"| {x['object']} | {x['mass_g']:.3f} | {fmt(x['f2_forward'])} | {fmt(x['f2_mc'])} | "
                     f"{fmt(x['rms_pct_forward'], 2)} | {fmt(x['rms_pct_mc'], 2)} |")
    m = doc["mean"]
    lines.append(f"| **mean** | | **{fmt(m['f2_forward'])}** | **{fmt(m['f2_mc'])}** | "
                 f"**{fmt(m['rms_pct_forward'], 2)}** | **{fmt(m['rms_pct_mc'], 2)}** |")
    return "\n".join(lines)


def plot_evaluation(results, path: Path) -> None:
    """Fig. 8: per object, measured vs forward model (leave-one-out) vs Monte Carlo (mean and 2 sigma)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(len(results), 3)
    nrows = math.ceil(len(results) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.3 * cols, 3.4 * nrows), dpi=110, squeeze=False, sharey=True)
    fmt = (lambda v: "n/a" if v is None else f"{v:.0f}")
    for ax, r in zip(axes.flat, results):
        h = r.t_s / 3600.0
        ax.plot(h, r.measured_g, color="k", lw=2.2, label="measured")
        ax.plot(h, r.forward_g, color="C3", lw=1.5, label="forward model (leave-one-out)")
        ax.fill_between(h, r.mc_g - 2 * r.mc_std_g, r.mc_g + 2 * r.mc_std_g, color="C0", alpha=0.25, lw=0)
        ax.plot(h, r.mc_g, "--", color="C0", lw=1.5, label="Monte Carlo (leave-one-out)")
        ax.set_title(f"{r.name}\nforward f2 {fmt(r.f2['forward'])}, RMS {r.rms_pct['forward']:.1f}% | "
                     f"MC f2 {fmt(r.f2['mc'])}, RMS {r.rms_pct['mc']:.1f}%", fontsize=7.5)
        ax.set_xlabel("time (h)")
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("released (g)")
    for ax in list(axes.flat)[len(results):]:
        ax.axis("off")
    axes[0, 0].legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
