"""The barrier loop on the simulated bench, through camera frames (docs/evidence/materials.md).

1. a bench calibration series, then release runs of uncoated calibration prints and of coated prints (a drug box
   in a uniform clear coat), each rendered frame by frame and analysed like any run;
2. ``calibrate-sim`` on them (a ``barrier_mesh`` column names the coated rows): the drug's calibration and the
   barrier's speed s with its standard error, against the bench's hidden s;
3. a delayed-release print (a drug slab under a clear lid in a thick-walled cup: a delay, then a constant rate)
   run on the bench: its measured curve is the target of a two-material design through the calibration, at the
   calibrated barrier speed (``sfr design --target CURVE --simcal SIMCAL --barrier-speed``'s job);
4. the designed print (design.stl in the envelope of both materials) released on the bench and measured: its curve
   against the delayed print's (RMS in % of the measured final release).

The bench's material is :meth:`Material.draw`'s hidden rate, density and barrier speed without print physics (the
two-material design's model is isotropic; see docs/materials.md). ``OUT/summary.json`` holds every number and
``OUT/barrier_loop.png`` the curves.

    python -m studies.barrier_loop OUT [--quick] [--resolution 48] [--design-resolution 40] [--max-iter 150]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import trimesh

from analysis import analyze_run, write_curve_csv
from design.inverse.twomaterial_problem import TwoMaterialSettings
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.simbench import Material, sample_release
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.jobs.demo import calibration_mesh, simulated_calibration, simulated_run
from labapp.jobs.design_barrier_measured import design_barrier_measured
from labapp.records.simcal import load_simcal

UNCOATED = ("flat", "tall", "sphere")
"""The drug's calibration prints (the demo's)."""
COATED_PRINTS = 3
DRUG_BOX_MM, COAT_MM = (12.0, 12.0, 6.0), 0.6
"""The coated prints: a drug box in a coat grown by COAT_MM on every face."""
SLAB_MM, LID_MM, WALL_MM = (12.0, 12.0, 3.0), 0.6, 3.0
"""The delayed print: a drug slab under a lid LID_MM thick, in a cup whose walls and floor are WALL_MM thick."""
INTERVAL_S = 60.0


def coated_box() -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    """The coated calibration print: (drug, barrier block)."""
    drug = trimesh.creation.box(DRUG_BOX_MM)
    return drug, trimesh.creation.box(np.asarray(DRUG_BOX_MM) + 2 * COAT_MM)


def delayed_print() -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    """The delayed-release print: (drug slab, barrier block holding it, its top LID_MM below the block's)."""
    x, y, z = SLAB_MM
    block = np.array([x + 2 * WALL_MM, y + 2 * WALL_MM, z + WALL_MM + LID_MM])
    drug = trimesh.creation.box(SLAB_MM)
    drug.apply_translation([0.0, 0.0, 0.5 * block[2] - LID_MM - 0.5 * z])
    return drug, trimesh.creation.box(block)


def _run(clock, cal, release, runs: Path, index: int, min_duration_s: float | None = None) -> tuple[Path, dict]:
    """A release run through the camera and its analysed curve; returns the run folder and its numbers."""
    t0 = time.process_time()
    run = simulated_run(clock, cal, release, runs, interval_s=INTERVAL_S, hotplate=False, min_duration_s=min_duration_s,
                        seed=index)
    curve = analyze_run(run, cal, cache_dir=run / "analysis")
    write_curve_csv(curve, run / "analysis" / "curve.csv")
    return run, {"name": release.name, "index": index, "frames": len(curve.t_s), "mass_g": release.mass_g,
                 "truth": release.truth, "cpu_s": time.process_time() - t0}


def _write_meshes(folder: Path, meshes: dict) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, mesh in meshes.items():
        mesh.export(folder / f"{name}.stl")


def calibrate(out: Path, material: Material, clock, resolution: int, times: dict) -> tuple[dict, Path]:
    """Steps 1-2: the bench calibration, the runs of uncoated and coated prints, and ``calibrate-sim``."""
    t0 = time.process_time()
    cal, cal_path = simulated_calibration(out / "calibration", clock)
    drug, coat = coated_box()
    _write_meshes(out / "meshes", {**{n: calibration_mesh(n) for n in UNCOATED}, "box": drug, "box_coat": coat})
    rows, runs = ["run,mesh,object_mass_g,barrier_mesh"], []
    for index, name in enumerate(UNCOATED):
        release = sample_release(name, index, material=material, mesh=calibration_mesh(name))
        run, info = _run(clock, cal, release, out / "runs", index)
        rows.append(f"{run.relative_to(out)},meshes/{name}.stl,,")
        runs.append(info)
    for k in range(COATED_PRINTS):
        index = len(UNCOATED) + k
        release = sample_release("coated-box", index, material=material, mesh=drug, barrier=coat)
        run, info = _run(clock, cal, release, out / "runs", index, min_duration_s=0.9 * release.duration_s)
        rows.append(f"{run.relative_to(out)},meshes/box.stl,,meshes/box_coat.stl")
        runs.append(info)
    set_csv = out / "calibration_set.csv"
    set_csv.write_text("\n".join(rows) + "\n")
    times["bench_runs_cpu_s"] = time.process_time() - t0
    t0 = time.process_time()
    result = calibrate_sim(set_csv, cal_path, out / "simcal", resolution=resolution, physics="none")
    times["calibrate_sim_cpu_s"] = time.process_time() - t0
    return {"runs": runs, "barrier": result.doc["barrier"], "seconds_per_mm": result.doc["seconds_per_mm"],
            "g_per_mm3": result.doc["g_per_mm3"], "loo_rel_rmse_mean": result.doc["loo_rel_rmse_mean"]}, cal_path


def bench_pair(design: Path) -> tuple[trimesh.Trimesh, trimesh.Trimesh, float]:
    """The designed print as the bench releases it: (drug, envelope of both materials, barrier inclusions mm^3).

    The bench's evaluator models closed drug bodies without voids, so barrier wholly enclosed by drug (a few voxels
    the design's print extraction leaves) is printed as drug; its volume is returned.
    """
    from scipy import ndimage

    from design.fabrication.extract import density_mesh

    fields = np.load(design / "fields.npz")
    dx, origin = float(fields["dx_mm"]), fields["origin_mm"]
    drug = ndimage.binary_fill_holes(fields["drug"])
    inclusions = float(np.count_nonzero(drug & ~fields["drug"])) * dx ** 3
    drug_mesh = density_mesh(drug.astype(float), dx, origin) if inclusions else trimesh.load(design / "design.stl")
    return drug_mesh, density_mesh((drug | fields["barrier"]).astype(float), dx, origin), inclusions


def _curve(run: Path) -> tuple[np.ndarray, np.ndarray]:
    data = np.genfromtxt(run / "analysis" / "curve.csv", delimiter=",", names=True)
    return data["t_s"], data["released_g"]


def _rel_rmse(t_a, g_a, t_b, g_b) -> float:
    """RMS of curve a against curve b on b's times (a held at its last value after its end), / b's final."""
    a = np.interp(t_b, t_a, g_a)
    return float(np.sqrt(np.mean((a - g_b) ** 2)) / np.max(g_b))


def loop(out: Path, resolution: int = 48, design_resolution: int = 40, max_iter: int = 150,
         material: Material | None = None) -> dict:
    """The whole loop of the module docstring into ``out``; returns the summary (also ``out/summary.json``)."""
    material = material or dataclasses.replace(Material.draw(), physics=None)
    clock, times, wall = SteppedClock(), {}, time.monotonic()
    out.mkdir(parents=True, exist_ok=False)
    calibration, cal_path = calibrate(out, material, clock, resolution, times)
    simcal = load_simcal(out / "simcal" / "simcal.json")
    from analysis import BenchCalibration
    cal = BenchCalibration.load(cal_path)

    t0 = time.process_time()
    drug, block = delayed_print()
    _write_meshes(out / "meshes", {"delayed": drug, "delayed_barrier": block})
    target_release = sample_release("delayed", 10, material=material, mesh=drug, barrier=block)
    target_run, target_info = _run(clock, cal, target_release, out / "runs", 10,
                                   min_duration_s=0.9 * target_release.duration_s)
    times["delayed_run_cpu_s"] = time.process_time() - t0

    t0 = time.process_time()
    speed = simcal.barrier["speed"]
    dx = LID_MM / max(1, round(LID_MM / (2.4 * (LID_MM / speed + SLAB_MM[2]) / design_resolution)))
    settings = TwoMaterialSettings(str(target_run / "analysis" / "curve.csv"), speed, resolution=design_resolution,
                                   domain_mm=dx * design_resolution, max_iter=max_iter)
    design = design_barrier_measured(settings, out / "design", simcal, speed_source="calibrated", reference=False)
    physical = json.loads((out / "design" / "physical.json").read_text())
    times["design_cpu_s"] = time.process_time() - t0

    t0 = time.process_time()
    printed, envelope, inclusions_mm3 = bench_pair(out / "design")
    design_release = sample_release("design", 11, material=material, mesh=printed, barrier=envelope)
    design_run, design_info = _run(clock, cal, design_release, out / "runs", 11,
                                   min_duration_s=0.9 * design_release.duration_s)
    times["design_run_cpu_s"] = time.process_time() - t0
    t_target, g_target = _curve(target_run)
    t_design, g_design = _curve(design_run)
    designed = np.genfromtxt(out / "design" / "curves_physical.csv", delimiter=",", names=True)
    s = design.summary
    summary = {
        "hidden_barrier_speed": material.barrier_speed, "barrier": calibration["barrier"],
        "barrier_error_in_se": (calibration["barrier"]["speed"] - material.barrier_speed) / calibration["barrier"]["error"],
        "hidden_seconds_per_mm": material.seconds_per_mm, "calibration": calibration,
        "delayed_print": target_info, "design_print": design_info,
        "design": {"resolution": design_resolution, "domain_mm": settings.domain_mm, "voxel_size_mm": dx,
                   "max_iter": max_iter, "status": s["status"], "density_fit": s["density_fit"], "grid_fit": s["grid_fit"],
                   "reference_fit": s["reference_fit"], "cover_mm": s["barrier"]["cover_mm"],
                   "release_starts_mm": s["barrier"]["release_starts_mm"], "pieces": s["print_pieces"],
                   "drug_mm3": s["drug"]["volume_mm3"], "barrier_mm3": s["barrier"]["volume_mm3"],
                   "inclusions_printed_as_drug_mm3": inclusions_mm3, **physical},
        "bench": {"rel_rmse_design_print_vs_measured": _rel_rmse(t_design, g_design, t_target, g_target),
                  "rel_rmse_design_print_vs_prediction": _rel_rmse(t_design, g_design, designed["t_s"],
                                                                   designed["design_released_g"]),
                  "measured_final_g": float(np.max(g_target)), "design_print_final_g": float(np.max(g_design))},
        "cpu_s": times, "wall_s": time.monotonic() - wall,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    _plot(out, calibration, (t_target, g_target), (t_design, g_design), designed, summary)
    return summary


def _plot(out: Path, calibration: dict, target, design, designed, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.4), dpi=110)
    for i, row in enumerate(calibration["barrier"]["runs"]):
        t, g = _curve(Path(row["run"]))
        left.plot(t / 3600, g, color=f"C{i}", label=f"coated print {i + 1}: s = {row['speed']:.4f}")
    b = calibration["barrier"]
    left.set_title(f"coated prints: s = {b['speed']:.4f} +- {b['error']:.4f} (hidden {summary['hidden_barrier_speed']:.4f})",
                   fontsize=10)
    right.plot(target[0] / 3600, target[1], color="C0", lw=2.5, label="delayed print: measured (the target)")
    right.plot(designed["t_s"] / 3600, designed["design_released_g"], "--", color="C2", label="design: predicted")
    right.plot(design[0] / 3600, design[1], color="C3", lw=1.5,
               label=f"design's print: measured ({100 * summary['bench']['rel_rmse_design_print_vs_measured']:.1f} % RMS)")
    right.set_title("a design from the measured delayed curve, printed and measured", fontsize=10)
    for ax in (left, right):
        ax.set_xlabel("time since drop (h)")
        ax.set_ylabel("released (g)")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "barrier_loop.png")
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--resolution", type=int, default=48, help="calibrate-sim's resolution")
    parser.add_argument("--design-resolution", type=int, default=40)
    parser.add_argument("--max-iter", type=int, default=150)
    parser.add_argument("--quick", action="store_true", help="resolution 24, design resolution 24, 30 evaluations")
    args = parser.parse_args(argv)
    if args.quick:
        args.resolution, args.design_resolution, args.max_iter = 24, 24, 30
    s = loop(args.out, args.resolution, args.design_resolution, args.max_iter)
    b = s["barrier"]
    per_run = ", ".join(f"{r['speed']:.4f}" for r in b["runs"])
    print(f"barrier speed: hidden {s['hidden_barrier_speed']:.4f}, recovered {b['speed']:.4f} +- {b['error']:.4f} "
          f"({s['barrier_error_in_se']:+.2f} SE); per run {per_run}")
    d = s["design"]
    print(f"design ({d['resolution']}, dx {d['voxel_size_mm']:.3f} mm): density fit {d['density_fit']:.3f}, grid fit "
          f"{d['grid_fit']:.3f}, reference fit {d['reference_fit']}, predicted vs measured {d['rel_rmse_physical']:.3f}")
    print(f"bench: design's print vs the measured delayed curve {s['bench']['rel_rmse_design_print_vs_measured']:.3f}, "
          f"vs its prediction {s['bench']['rel_rmse_design_print_vs_prediction']:.3f}")
    print(f"CPU s {s['cpu_s']}, wall {s['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
