"""The paper's isotropic model and the calibrated-physics model side by side on a bench whose physics is not the model's.

The bench (``labapp.acquisition.printworld``) releases each print by its own hidden physics: a material drawn by
``Material.draw(seed)`` (rate, density, and ``PrintPhysics.draw``: anisotropy, surface offset, swelling width,
wetting lag), each print with its own few-percent rate and density, computed on the world's own grid by
scikit-fmm. Each run is the print's release sampled every 30 s with 0.2%-of-mass noise (the camera pipeline's
noise on the simulated bench is of that order; the pipeline itself is exercised by ``sfr demo``).

1. Four calibration prints (the flat slab and tall column ``sfr calibrate-sim --plan`` proposes for anisotropy, a
   sphere, a bar lying down; with ``--channelled`` also the slab with three 0.5 mm slots that ``--plan`` proposes for
   the swelling width, with ``--add-prints`` further ones) and unseen ones (the pill lying along x, a wafer, csg).
2. ``calibrate-sim --physics none`` (isotropic) and ``--physics auto`` (anisotropy, offset and wetting lag: every
   subset; the swelling width needs channelled prints) on the four, resolution ``--resolution``:
   honest leave-one-out (print physics refitted without each run), the recovered parameters with their
   uncertainties against the hidden ones, and the error bands' leave-one-out coverage.
3. The unseen print predicted from its mesh by each calibration, with its band.
4. With ``--design``: a design (``sfr design --simcal``'s job) for an unseen print's measured curve (``--design-for``:
   the pill, or a flat wafer) through each calibration, in the design space and domain given (``--design-space``,
   ``--design-domain``, ``--design-height``: e.g. an extruded prism, printable without supports, for the wafer's
   curve), its ``design.stl`` printed on the bench (released by the bench's hidden physics), against the measured
   target: RMS % of the final mass.
5. The plan's Cramer-Rao standard error of the anisotropy for these calibration prints, against the jackknife over
   the leave-one-out refits (without the discretisation term the stated uncertainty adds).

    nice -n 10 .venv/bin/python -m benchmarks.physics_loop --out /tmp/physics_loop --seed 11 [--design]

Prints a markdown table and writes ``physics_loop_SEED.png`` (and ``physics_loop_design_SEED.png``) into
``--docs`` (default ``docs/figures``) and ``results.json`` into ``--out`` (with a design other than the pill's nfc one,
``results_FOR_SPACE.json``).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

WORLD_RESOLUTION = 96
"""Voxels along the longest side of the bench's own release computation."""
INTERVAL_S, NOISE, WATER_G = 30.0, 0.002, 500.0
UNSEEN = "pill"
DESIGN_TARGETS = (UNSEEN, "wafer")
"""Prints whose measured curve ``--design-for`` may take as the design's target: the unseen pill, or an unseen flat
wafer (a disc 18 mm across and 3.2 mm thick, released mostly through its faces along the build direction)."""
UNSEEN_PRINTS = (*DESIGN_TARGETS, "csg")
"""The prints no calibration sees: the pill (the figure's), the wafer and the csg sample (12 mm tall, with a
through-hole), each predicted from its mesh by every calibration."""
DESIGN_BAR = 0.03
"""A design printed on the bench must match its measured target within this RMS fraction of the final mass."""
LABELS = {"none": "isotropic"}
"""Column names: ``--physics none`` is the paper's isotropic model; the others are named by their --physics."""


def _even_voxels(side_mm: float, longest_mm: float, resolution: int) -> float:
    """The side nearest ``side_mm`` that is an even number of voxels of a grid of ``resolution`` voxels along
    ``longest_mm``: the calibration's binary voxelisation (voxel centres, grid centred on the mesh) then holds a
    box's volume exactly."""
    dx = longest_mm / resolution
    return 2 * max(round(side_mm / (2 * dx)), 1) * dx


def _meshes(resolution: int | None = None, channelled: bool = False, added: tuple[str, ...] = ()):
    """The calibration prints and the unseen ones; with ``resolution``, the boxes' short sides are whole even
    numbers of voxels at it (see `_even_voxels`); with ``channelled``, a fifth calibration print: the slab with three
    0.5 mm slots that ``--plan`` proposes for the swelling width; ``added``: further calibration prints (shipped
    samples or ``--plan``'s generated shapes, by name), after the unseen prints so that every other print keeps its
    index and so its own rate and density draw."""
    import trimesh

    from design.geometry.shapes import sample_shape
    from labapp.jobs.plan import GENERATED

    flat, bar = GENERATED["flat"][0](), trimesh.creation.box((22.0, 6.0, 6.0))
    if resolution is not None:
        flat = trimesh.creation.box((18.0, 18.0, _even_voxels(4.0, 18.0, resolution)))
        side = _even_voxels(6.0, 22.0, resolution)
        bar = trimesh.creation.box((22.0, side, side))
    return {"flat": flat, "tall": GENERATED["tall"][0](), "sphere": sample_shape("sphere"), "bar": bar,
            **({"channelled": GENERATED["channelled"][0]()} if channelled else {}), UNSEEN: sample_shape(UNSEEN),
            "wafer": trimesh.creation.cylinder(radius=9.0, height=3.2, sections=96), "csg": sample_shape("csg"),
            **{name: GENERATED[name][0]() if name in GENERATED else sample_shape(name) for name in added}}


def bench_run(mesh, name: str, material, index: int, folder: Path) -> tuple[Path, float]:
    """One print released by the bench's physics, written as a curve CSV; returns (path, weighed mass g)."""
    from labapp.acquisition.printworld import world_release
    from labapp.acquisition.simbench import SampleRelease

    world = world_release(mesh, material.physics, resolution=WORLD_RESOLUTION)
    release = SampleRelease.from_simulation(name, world.tau_mm, world.released_mm3, *material.printed(index),
                                            lag_s=material.physics.wetting_lag_s)
    t = np.arange(INTERVAL_S, 1.15 * release.duration_s, INTERVAL_S)
    grams = np.interp(t, release.t_s, release.released_g)
    grams = grams + NOISE * release.mass_g * np.random.default_rng(index).standard_normal(t.size)
    conc = grams / WATER_G * 1000.0
    path = folder / f"{name}.csv"
    np.savetxt(path, np.column_stack([t, conc, conc, grams]), delimiter=",", comments="",
               header="t_s,conc_g_per_kg,conc_smooth_g_per_kg,released_g", fmt="%.6f")
    return path, release.mass_g


def calibrate(set_csv: Path, out: Path, physics: str, resolution: int):
    """``calibrate-sim`` on the set; a calibration already in ``out`` (a rerun with ``--reuse``) is read back."""
    from labapp.jobs.calibrate_sim import SimCalRun, calibrate_sim

    if (out / "simcal.json").is_file():
        return SimCalRun(json.loads((out / "simcal.json").read_text()), (), out / "simcal.json"), 0.0
    start = time.perf_counter()
    run = calibrate_sim(set_csv, None, out, model="constant", resolution=resolution, physics=physics,
                        progress=lambda f, m: print(f"   [{physics}] {m}", flush=True) if f in (0.0, 1.0) else None)
    return run, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--seed", type=int, default=11, help="the bench's hidden material draw")
    parser.add_argument("--resolution", type=int, default=40)
    parser.add_argument("--physics", default="none,auto",
                        help="the calibrate-sim --physics of each column (none: the paper's isotropic model)")
    parser.add_argument("--without", default="",
                        help="effects of the hidden draw to switch off (comma-separated PrintPhysics fields, e.g. "
                             "wetting_lag_s; 'all' for a bench whose prints dissolve as the isotropic model says)")
    parser.add_argument("--mesh-boxes", action="store_true",
                        help="the flat slab 18 x 18 x 4 mm and the bar 22 x 6 x 6 mm as designed, whatever the voxels "
                             "(default: their short sides an even number of voxels at --resolution)")
    parser.add_argument("--channelled", action="store_true",
                        help="a fifth calibration print, the channelled slab, so that the swelling width can be learned")
    parser.add_argument("--add-prints", default="",
                        help="further calibration prints, comma-separated: shipped samples or --plan's shapes (e.g. "
                             "spinner_top, which --plan proposes for the offset)")
    parser.add_argument("--reuse", action="store_true", help="reuse the runs and calibrations already in --out")
    parser.add_argument("--design", action="store_true", help="also design for the unseen print's measured curve")
    parser.add_argument("--design-for", choices=DESIGN_TARGETS, default=UNSEEN,
                        help="the unseen print whose measured curve the design takes as its target")
    parser.add_argument("--design-space", choices=("nfc", "extruded"), default="nfc")
    parser.add_argument("--design-domain", default="",
                        help="the design's domain X,Y,Z in mm (default: the design's own, a cube)")
    parser.add_argument("--design-height", type=float, default=None, help="an extruded design's height, mm")
    parser.add_argument("--design-starts", type=int, default=None,
                        help="the design's starts (sfr design --starts; default the design's own)")
    parser.add_argument("--design-resolution", type=int, default=40)
    parser.add_argument("--design-iterations", type=int, default=100)
    parser.add_argument("--docs", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "figures")
    args = parser.parse_args()
    run_loop(args)


def run_loop(args) -> dict:
    from analysis.bands import inside
    from labapp.acquisition.simbench import Material
    from labapp.jobs.bands import prediction_band, source_simulator
    from labapp.records.simcal import load_simcal

    start = time.perf_counter()
    if args.out.exists() and not args.reuse:
        raise SystemExit(f"{args.out} exists; choose a new --out (or --reuse it)")
    runs_dir = args.out / "runs"
    material = Material.draw(args.seed)
    effects = ("anisotropy", "offset_mm", "swelling_mm", "wetting_lag_s") if args.without == "all" else \
        tuple(e for e in args.without.split(",") if e)
    material = dataclasses.replace(material, physics=material.physics.without(*effects))
    added = tuple(n for n in args.add_prints.split(",") if n)
    meshes = _meshes(None if args.mesh_boxes else args.resolution, args.channelled, added)
    names = [n for n in meshes if n not in UNSEEN_PRINTS]
    set_csv = runs_dir / "set.csv"
    runs_dir.mkdir(parents=True, exist_ok=True)
    rows, masses = ["run,mesh,object_mass_g"], {}
    for index, (name, mesh) in enumerate(meshes.items()):   # each print's own rate and density draw: by its index
        if (runs_dir / f"{name}.csv").is_file():
            continue   # a run already made (--reuse)
        mesh.export(runs_dir / f"{name}.stl")
        path, masses[name] = bench_run(mesh, name, material, index, runs_dir)
        if name not in UNSEEN_PRINTS:
            rows.append(f"{path.name},{name}.stl,{masses[name]:.4f}")
        print(f"  {name}: {masses[name]:.3f} g ({time.perf_counter() - start:.0f} s)", flush=True)
    if not set_csv.is_file():
        set_csv.write_text("\n".join(rows) + "\n")

    results = {"seed": args.seed, "without": list(effects), "mesh_boxes": args.mesh_boxes, "channelled": args.channelled,
               "added_prints": list(added),
               "extents": {n: [round(float(x), 3) for x in m.extents] for n, m in meshes.items()},
               "hidden": dataclasses.asdict(material.physics),
               "material": {"seconds_per_mm": material.seconds_per_mm, "density_g_per_cm3": material.density_g_per_cm3},
               "resolution": args.resolution, "models": {}}
    unseen = np.genfromtxt(runs_dir / f"{UNSEEN}.csv", delimiter=",", names=True)
    for physics in args.physics.split(","):
        label = LABELS.get(physics, physics)
        run, seconds = calibrate(set_csv, args.out / label, physics, args.resolution)
        doc = run.doc
        simcal = load_simcal(run.path)
        choice = doc["physics"]["choice"]
        candidate = doc["physics"]["candidates"].get(choice)
        honest = ([c["rel_rmse"] for c in candidate["loo"]] if candidate else [r["rel_rmse"] for r in doc["loo"]])
        simulate_at = source_simulator(str(runs_dir / f"{UNSEEN}.stl"), simcal.resolution)
        tau, vol = simulate_at(simcal.physics)
        predicted = simcal.cal.to_physical(tau, vol, unseen["t_s"], WATER_G)
        band = prediction_band(simcal, tau, vol, unseen["t_s"], WATER_G, simulate_at)
        final = float(unseen["released_g"].max())
        # the same print predicted from its weighed mass (the measured plateau): the shape's error alone
        weighed = simcal.cal.to_physical(tau, vol, unseen["t_s"], WATER_G, mass_g=float(np.mean(unseen["released_g"][-10:])))
        results["models"][label] = {
            "physics_choice": choice, "fitted": doc["physics"]["fitted"],
            "values": {p: doc["physics"][p] for p in doc["physics"]["fitted"]},
            "uncertainty": doc["physics"]["uncertainty"], "seconds_per_mm": doc["seconds_per_mm"],
            # the spread of the leave-one-out refits alone (the stated uncertainty adds the discretisation bias)
            "uncertainty_refits": doc["physics"].get("discretisation", {}).get("uncertainty_refits",
                                                                             doc["physics"]["uncertainty"]),
            "discretisation": doc["physics"].get("discretisation"),
            "loo_per_run": dict(zip(names, honest)), "loo_mean": float(np.mean(honest)),
            "band_coverage": doc["band"]["loo_coverage"],
            "unseen_rel_rmse": float(np.sqrt(np.mean((predicted - unseen["released_g"]) ** 2)) / final),
            "unseen_inside_band": inside(unseen["released_g"], *band),
            "unseen_weighed_rel_rmse": float(np.sqrt(np.mean((weighed - unseen["released_g"]) ** 2)) / final),
            "density_g_per_cm3": doc["density_g_per_cm3"],
            "unseen": {"predicted": predicted.tolist(), "lower": band[0].tolist(), "upper": band[1].tolist()},
            "unseen_prints": {n: unseen_errors(runs_dir, n, simcal) for n in UNSEEN_PRINTS},
            "candidates": {k: c["loo_rel_rmse_mean"] for k, c in doc["physics"]["candidates"].items()},
            "seconds": seconds, "simcal": str(run.path)}
        print(f"  {label}: {choice}, leave-one-out {100 * np.mean(honest):.2f}%, unseen "
              f"{100 * results['models'][label]['unseen_rel_rmse']:.2f}% ({seconds:.0f} s)", flush=True)
    results["floor"] = {n: floor_errors(runs_dir, n, meshes[n], material, args.resolution) for n in UNSEEN_PRINTS}
    results["plan_check"] = plan_check(meshes, names, results, args.resolution)
    if args.design:
        results["design"] = design_check(args, runs_dir, material, results)
    results["wall_s"] = time.perf_counter() - start
    name = f"results{_design_suffix(args)}.json" if args.design else "results.json"
    (args.out / name).write_text(json.dumps(results, indent=2) + "\n")
    figure(results, unseen, args)
    print(table(results))
    return results


def _curve(runs_dir: Path, name: str):
    return np.genfromtxt(runs_dir / f"{name}.csv", delimiter=",", names=True)


def _errors(curve, predicted_g, weighed_g) -> dict:
    """RMS error of a prediction from the mesh and from the weighed mass, fractions of the measured final mass."""
    final = float(curve["released_g"].max())
    return {"mesh": float(np.sqrt(np.mean((predicted_g - curve["released_g"]) ** 2)) / final),
            "weighed": float(np.sqrt(np.mean((weighed_g - curve["released_g"]) ** 2)) / final)}


def _weighed_mass(curve) -> float:
    """The print's mass as the bench weighs it: the measured plateau (the last ten points)."""
    return float(np.mean(curve["released_g"][-10:]))


def unseen_errors(runs_dir: Path, name: str, simcal) -> dict:
    """An unseen print's prediction from its mesh through a calibration: from the pooled density and from its
    weighed mass."""
    from labapp.jobs.bands import source_simulator

    curve = _curve(runs_dir, name)
    tau, vol = source_simulator(str(runs_dir / f"{name}.stl"), simcal.resolution,
                                method=simcal.release_method)(simcal.physics)
    predicted = simcal.cal.to_physical(tau, vol, curve["t_s"], WATER_G)
    weighed = simcal.cal.to_physical(tau, vol, curve["t_s"], WATER_G, mass_g=_weighed_mass(curve))
    return _errors(curve, predicted, weighed)


def floor_errors(runs_dir: Path, name: str, mesh, material, resolution: int) -> dict:
    """The error floor of an unseen print's prediction: the calibration's release with the bench's hidden physics
    (``print_release``'s, at ``resolution``) mapped by the material's mean rate and density and its
    wetting lag. What is left is each print's own rate and density draw and the bench's noise, which no calibration
    can know."""
    from design.files.pipeline import mesh_grid
    from labapp.jobs.printrelease import print_release

    hidden = material.physics
    physics = {"anisotropy": hidden.anisotropy, "offset_mm": hidden.offset_mm, "swelling_mm": hidden.swelling_mm}
    grid = mesh_grid(mesh, resolution=resolution, offset_mm=physics["offset_mm"])
    tau, vol = print_release(mesh, grid, resolution, physics)
    curve = _curve(runs_dir, name)
    depth = np.clip((curve["t_s"] - hidden.wetting_lag_s) / material.seconds_per_mm, 0.0, None)
    released = np.interp(depth, tau, vol)
    return _errors(curve, released * material.density_g_per_cm3 * 1e-3,
                   released / vol[-1] * _weighed_mass(curve))


def plan_check(meshes: dict, names: list[str], results: dict, resolution: int) -> dict | None:
    """The plan's Cramer-Rao standard error of the anisotropy for the calibration prints, with the
    anisotropy model's own leave-one-out RMS as the error at each of `PLAN_POINTS` points, against its jackknife."""
    from labapp.jobs.plan import PLAN_POINTS, expected_std, sensitivity

    fitted = [m for m in results["models"].values() if "anisotropy" in m["fitted"]]
    if not fitted:
        return None
    model = fitted[0]
    parameters = ("log_seconds", "anisotropy")
    jac = [sensitivity(meshes[n], parameters, resolution=resolution) for n in names]
    noise = model["loo_mean"]
    return {"noise": noise, "points": PLAN_POINTS, "prints": len(names),
            "expected_std_anisotropy": expected_std(parameters, jac, noise)["anisotropy"],
            "jackknife_anisotropy": model["uncertainty_refits"]["anisotropy"]}


def design_check(args, runs_dir: Path, material, results: dict) -> dict:
    """A design for an unseen print's measured curve (``--design-for``) through each calibration (once per distinct
    physics), printed on the bench."""
    import trimesh

    from design.inverse.config import DesignConfig
    from labapp.acquisition.printworld import world_release
    from labapp.acquisition.simbench import SampleRelease
    from labapp.jobs.physical import design_from_target
    from labapp.records.simcal import load_simcal

    target_csv = runs_dir / f"{args.design_for}.csv"
    if not target_csv.is_file():
        raise SystemExit(f"{target_csv} is missing: the runs in {runs_dir} were made without the {args.design_for} print")
    target = np.genfromtxt(target_csv, delimiter=",", names=True)
    domain = tuple(float(x) for x in args.design_domain.split(",")) if args.design_domain else None
    final = float(target["released_g"].max())
    out, done = {}, {}
    for label, model in results["models"].items():
        key = json.dumps([model["physics_choice"], model["values"]], sort_keys=True)
        if key in done:
            out[label] = out[done[key]]
            continue
        done[key] = label
        simcal = load_simcal(model["simcal"])
        config = DesignConfig(target=str(target_csv), space=args.design_space, resolution=args.design_resolution,
                              domain_mm=domain, height_mm=args.design_height, max_iter=args.design_iterations,
                              starts=args.design_starts,
                              allow_infeasible=True)
        start = time.perf_counter()
        folder = args.out / (f"design_{label}{_design_suffix(args)}_{args.design_iterations}"
                             + (f"_starts{args.design_starts}" if args.design_starts else ""))
        resume = (folder / "config.json").is_file()  # a design begun (or finished) before: resumed
        result, summary = design_from_target(None if resume else config, folder, simcal=simcal, resume=resume)
        mesh = trimesh.load(result.out_dir / "design.stl")
        world = world_release(mesh, material.physics, resolution=WORLD_RESOLUTION)
        printed = SampleRelease.from_simulation("design", world.tau_mm, world.released_mm3, *material.printed(50),
                                                lag_s=material.physics.wetting_lag_s)
        grams = np.interp(target["t_s"], printed.t_s, printed.released_g)
        out[label] = {"rel_rmse_printed": float(np.sqrt(np.mean((grams - target["released_g"]) ** 2)) / final),
                      "rel_rmse_predicted": summary["rel_rmse_physical"], "print_mass_g": printed.mass_g,
                      "target_mass_g": final, "printed": grams.tolist(), "status": str(result.status),
                      "band_target_inside": (summary.get("band") or {}).get("target_inside_fraction"),
                      "seconds": time.perf_counter() - start, "folder": str(result.out_dir)}
        print(f"  design ({label}): printed on the bench {100 * out[label]['rel_rmse_printed']:.2f}% of the final "
              f"mass, predicted {100 * summary['rel_rmse_physical']:.2f}%", flush=True)
    return {"for": args.design_for, "space": args.design_space, "domain_mm": domain, "height_mm": args.design_height,
            "t_s": target["t_s"].tolist(), "target_g": target["released_g"].tolist(), "models": out}


def _design_suffix(args) -> str:
    """The design folder's and figure's suffix naming a design other than the default (nfc, for the pill)."""
    parts = ([args.design_for] if args.design_for != UNSEEN else []) + \
        ([args.design_space] if args.design_space != "nfc" else [])
    return "".join(f"_{p}" for p in parts)


def _sigmas(value: float, hidden: float, sd: float) -> str:
    """How far a recovered value lies from the hidden one, in its stated standard errors."""
    return f"{abs(value - hidden) / sd:.1f} sd off" if sd > 0 else "no sd"


def table(results: dict) -> str:
    hidden = results["hidden"]
    models = results["models"]
    cols = list(models)

    def row(name: str, cell) -> str:
        return f"| {name} | " + " | ".join(cell(models[c], c) for c in cols) + " |"

    names = list(next(iter(models.values()))["loo_per_run"])
    lines = [f"Hidden draw (seed {results['seed']}): anisotropy {hidden['anisotropy']:.3f}, offset "
             f"{hidden['offset_mm']:.3f} mm, swelling {hidden['swelling_mm']:.2f} mm, wetting lag "
             f"{hidden['wetting_lag_s']:.0f} s; material {results['material']['seconds_per_mm']:.0f} s/mm, "
             f"{results['material']['density_g_per_cm3']:.3f} g/cm^3; calibration at resolution {results['resolution']}.", "",
             "| | " + " | ".join("isotropic (paper)" if c == "isotropic" else f"`--physics {c}`" for c in cols) + " |",
             "|---|" + "---|" * len(cols),
             row("physics kept (+- standard error; hidden)", lambda m, c: (m["physics_choice"] + ": " + ", ".join(
                 f"{p} {v:.3g} +- {m['uncertainty'][p]:.2g} ({hidden[p]:.3g}; {_sigmas(v, hidden[p], m['uncertainty'][p])})"
                 for p, v in m["values"].items())) if m["values"] else m["physics_choice"])]
    lines += [row(f"leave-one-out, {n}", lambda m, c, n=n: f"{100 * m['loo_per_run'][n]:.2f}%") for n in names]
    lines += [row("leave-one-out, mean", lambda m, c: f"{100 * m['loo_mean']:.2f}%"),
              *[row(f"unseen {n} from its mesh (from its weighed mass)",
                    lambda m, c, n=n: f"{100 * m['unseen_prints'][n]['mesh']:.2f}% "
                                      f"({100 * m['unseen_prints'][n]['weighed']:.2f}%)") for n in UNSEEN_PRINTS],
              row("unseen prints, mean from the mesh (from the weighed mass)", lambda m, c: "{:.2f}% ({:.2f}%)".format(
                  *(100 * np.mean([e[k] for e in m["unseen_prints"].values()]) for k in ("mesh", "weighed")))),
              row("pooled print density (hidden: see above)", lambda m, c: f"{m['density_g_per_cm3']:.3f} g/cm^3"),
              row("90% band: held-out points inside", lambda m, c: f"{100 * m['band_coverage']['fraction']:.0f}%"),
              row("90% band: unseen print's points inside", lambda m, c: f"{100 * m['unseen_inside_band']:.0f}%")]
    if "design" in results:
        d = results["design"]
        what = d.get("for", UNSEEN) + (f", {d['space']} design" if d.get("space", "nfc") != "nfc" else "")
        lines.append(row(f"design for the unseen {what}'s measured curve, printed on the bench (bar: 3%)",
                         lambda m, c: f"{100 * d['models'][c]['rel_rmse_printed']:.2f}% "
                                      f"({'within' if d['models'][c]['rel_rmse_printed'] <= DESIGN_BAR else 'misses'} "
                                      f"the bar; predicted {100 * d['models'][c]['rel_rmse_predicted']:.2f}%)"))
    floor = results["floor"]
    lines += ["", "Floor: the hidden physics with the material's mean rate and density predicts " + ", ".join(
        f"{n} {100 * e['mesh']:.2f}% ({100 * e['weighed']:.2f}%)" for n, e in floor.items())
        + f"; mean {100 * np.mean([e['mesh'] for e in floor.values()]):.2f}% "
          f"({100 * np.mean([e['weighed'] for e in floor.values()]):.2f}%). What is left is each print's own rate and "
          "density draw and the bench's noise."]
    plan = results.get("plan_check")
    if plan:
        lines += ["", f"Plan check: the Cramer-Rao standard error of the anisotropy for these {plan.get('prints', 4)} "
                      f"prints at the "
                      f"anisotropy model's leave-one-out error ({100 * plan['noise']:.2f}% at {plan['points']} points "
                      f"per run) is {plan['expected_std_anisotropy']:.3f}; its jackknife over the refits: "
                      f"{plan['jackknife_anisotropy']:.3f}."]
    return "\n".join(lines)


def figure(results: dict, unseen, args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    args.docs.mkdir(parents=True, exist_ok=True)
    hours = unseen["t_s"] / 3600.0
    labels = list(results["models"])
    fig, axes = plt.subplots(1, len(labels), figsize=(5.2 * len(labels), 4.2), dpi=110, sharey=True, squeeze=False)
    for ax, label in zip(axes[0], labels):
        m = results["models"][label]
        ax.fill_between(hours, m["unseen"]["lower"], m["unseen"]["upper"], color="C3", alpha=0.18, lw=0,
                        label="90% band of the prediction")
        ax.plot(hours, unseen["released_g"], color="C0", lw=2.2, label=f"{UNSEEN}: measured on the bench")
        ax.plot(hours, m["unseen"]["predicted"], "--", color="C3", lw=1.6, label="predicted from its mesh")
        design = results.get("design")
        if design and design["for"] == UNSEEN:
            printed = design["models"][label]
            ax.plot(hours, printed["printed"], "-", color="C2", lw=1.4,
                    label=f"design for it, printed ({100 * printed['rel_rmse_printed']:.1f}%)")
        kept = "isotropic (paper)" if label == "isotropic" else f"--physics {label}: {m['physics_choice']}"
        ax.set_title(f"{kept}\nleave-one-out {100 * m['loo_mean']:.2f}%, unseen {100 * m['unseen_rel_rmse']:.2f}%, "
                     f"band {100 * m['band_coverage']['fraction']:.0f}% / {100 * m['unseen_inside_band']:.0f}%",
                     fontsize=9)
        ax.set_xlabel("time since drop (h)")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=7)
    axes[0, 0].set_ylabel("released (g)")
    h = results["hidden"]
    fig.suptitle(f"bench with hidden physics (anisotropy {h['anisotropy']:.2f}, offset {h['offset_mm']:.2f} mm, "
                 f"swelling {h['swelling_mm']:.2f} mm, lag {h['wetting_lag_s']:.0f} s): an unseen print", fontsize=10)
    fig.tight_layout()
    suffix = ("" if not results["without"] else "_without_" + "_".join(e.split("_")[0] for e in results["without"])) \
        + ("_mesh_boxes" if results["mesh_boxes"] else "") + ("_channelled" if results.get("channelled") else "") \
        + "".join(f"_{name}" for name in results.get("added_prints", ()))
    fig.savefig(args.docs / f"physics_loop_{results['seed']}{suffix}.png")
    plt.close(fig)
    design = results.get("design")
    if design and design["for"] != UNSEEN:
        design_figure(results, design, args.docs / f"physics_loop_design_{results['seed']}{suffix}{_design_suffix(args)}.png")


def design_figure(results: dict, design: dict, path: Path) -> None:
    """The design's target (a measured curve) and each calibration's design printed on the bench."""
    import matplotlib.pyplot as plt

    hours = np.asarray(design["t_s"]) / 3600.0
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    ax.plot(hours, design["target_g"], color="C0", lw=2.4, label=f"{design['for']}: measured on the bench (target)")
    for k, (label, d) in enumerate(design["models"].items()):
        kept = "isotropic (paper)" if label == "isotropic" else f"--physics {label}"
        ax.plot(hours, d["printed"], "--" if k else ":", color=f"C{k + 1}", lw=1.8,
                label=f"{kept} design, printed: {100 * d['rel_rmse_printed']:.2f}% "
                      f"(its own prediction {100 * d['rel_rmse_predicted']:.2f}%)")
    ax.set_xlabel("time since drop (h)")
    ax.set_ylabel("released (g)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=7)
    h = results["hidden"]
    ax.set_title(f"{design['space']} design for the {design['for']}'s measured curve, printed on the bench\n"
                 f"(hidden anisotropy {h['anisotropy']:.2f}, offset {h['offset_mm']:.2f} mm, swelling "
                 f"{h['swelling_mm']:.2f} mm, lag {h['wetting_lag_s']:.0f} s)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    main()
