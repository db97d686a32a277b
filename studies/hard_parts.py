"""Evidence for docs/evidence/forward.md: `sfr simulate` at default flags on hard parts, against exact releases.

Builds each part with trimesh and manifold3d (long rods, plates with holes, thin-walled boxes open and sealed, a part
drawn in inches, tori, a sphere with a sealed void, files of two bodies touching, overlapping or apart, cubes,
cylinders, a sphere), writes it as an STL, runs ``sfr simulate PART`` (with ``--units in`` for the inch part) with
the checkout's command and with a BEFORE one, and compares each release.csv with the part's exact release on the
curve's own depths:

- analytic where the release has a closed form for the faceted solid (boxes, n-gon prisms, unions of boxes, a box
  around a concentric box void, and `benchmarks.analytic`'s sphere, torus and ball with an off-centre void);
- otherwise quasi-random: 2^20 scrambled Sobol points in the bounding box, each inside point's exact distance to the
  surface (point-triangle distances over a bounding-volume hierarchy, checked against brute force on a sample),
  released(tau) = V * (inside points with distance <= tau) / (inside points). That is the release of a solid whose
  every shell faces the bath (all such parts here), independent of the evaluator's lattice quadrature.

Prints one markdown row per part: RMS and max error over the curve and the final volume's error (% of the exact
volume), wall and CPU time (s, the command as a child process, numba's cache warm), and the method and lattice
(or grid) chosen.

With ``--prints``, parts printed with a calibration's surface offset (and anisotropy) instead (:func:`print_parts`):
each checkout's ``labapp.jobs.simulate.simulate(PART, physics=...)`` at its default model (what ``sfr simulate PART
--simcal simcal.json`` runs for a calibration with that physics), against the print's exact release: analytic for a
box (a box grown by o has rounded edges and Steiner's volume; shrunk, it is a smaller box, at any anisotropy), else
Sobol points' exact signed distances s with T = s + o in the print {s > -o} (exact for a shrink, and for a convex
solid or a smooth one of reach above o grown: `design.forward.offset_lattice`).

    python -m studies.hard_parts [--before /work/base] [--only NAME ...] [--work DIR] [--prints]
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

from benchmarks import analytic
from labapp.jobs.meshunits import MM_PER_UNIT

SOBOL_LOG2 = 20
"""2^20 quasi-random points per part without a closed form."""


def _box(dims, at=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    mesh = trimesh.creation.box(np.asarray(dims, float))
    mesh.apply_translation(at)
    return mesh


def _box_release(dims) -> Callable[[np.ndarray], np.ndarray]:
    dims = np.asarray(dims, float)
    return lambda t: np.prod(dims) - np.prod(np.clip(dims - 2 * np.asarray(t)[:, None], 0, None), axis=1)


def _prism_release(r: float, n: int, length: float) -> Callable[[np.ndarray], np.ndarray]:
    apothem = r * np.cos(np.pi / n)
    area = 0.5 * n * r * r * np.sin(2 * np.pi / n)

    def exact(t):
        t = np.asarray(t)
        return area * length - area * (np.clip(apothem - t, 0, None) / apothem) ** 2 * np.clip(length - 2 * t, 0, None)
    return exact


def _drilled(mesh: trimesh.Trimesh, holes: list[tuple[float, float, float]], height: float) -> trimesh.Trimesh:
    """``mesh`` with vertical through holes (x, y, diameter), mm."""
    cutters = []
    for x, y, d in holes:
        c = trimesh.creation.cylinder(radius=d / 2, height=height + 2.0, sections=64)
        c.apply_translation([x, y, 0.0])
        cutters.append(c)
    return trimesh.boolean.difference([mesh, *cutters], engine="manifold")


def _open_box(outer, wall: float) -> trimesh.Trimesh:
    """A box open at the top: ``outer`` dims less an inner box of walls ``wall`` that pokes out of the top."""
    a, b, c = outer
    inner = _box((a - 2 * wall, b - 2 * wall, c), (0.0, 0.0, wall))
    return trimesh.boolean.difference([_box(outer), inner], engine="manifold")


def _sealed_box(outer, wall: float) -> tuple[trimesh.Trimesh, Callable]:
    """A closed box with a concentric box void of walls ``wall``: the outer front reaches the void at tau = wall,
    when everything is gone, so the release is the outer box's, capped at the volume."""
    void = _box(np.asarray(outer) - 2 * wall)
    void.invert()
    volume = np.prod(outer) - np.prod(np.asarray(outer) - 2 * wall)
    return trimesh.util.concatenate([_box(outer), void]), lambda t: np.minimum(_box_release(outer)(t), volume)


def _bracket_in() -> trimesh.Trimesh:
    """An angle bracket drawn in inches: 2 x 1.5 in legs, 1/4 in thick, 1 in wide, two 1/4 in holes."""
    base = _box((2.0, 1.0, 0.25), (1.0, 0.5, 0.125))
    leg = _box((0.25, 1.0, 1.5), (0.125, 0.5, 0.75))
    body = trimesh.boolean.union([base, leg], engine="manifold")
    holes = []
    for x in (1.0, 1.6):
        c = trimesh.creation.cylinder(radius=0.125, height=1.0, sections=48)
        c.apply_translation([x, 0.5, 0.0])
        holes.append(c)
    return trimesh.boolean.difference([body, *holes], engine="manifold")


def parts() -> list[tuple[str, str, trimesh.Trimesh, str, Callable | None]]:
    """(name, what, mesh as written to the file, --units, analytic release in mm or None for Sobol)."""
    rod_cyl = trimesh.creation.cylinder(radius=1.5, height=45.0, sections=64)
    hollow, _, hollow_exact = analytic.hollow()
    sphere, _, sphere_exact = analytic.sphere()
    torus = trimesh.creation.torus(major_radius=20.0, minor_radius=3.0, major_sections=256, minor_sections=64)
    r = np.sqrt(torus.volume / (2 * np.pi ** 2 * 20.0))
    sealed, sealed_exact = _sealed_box((40.0, 30.0, 20.0), 2.0)
    cube_a, cube_b = _box((10, 10, 10)), _box((10, 10, 10), (6.0, 0.0, 0.0))
    stacked_a, stacked_b = _box((10, 10, 10)), _box((6, 6, 6), (0.0, 0.0, 8.0))
    apart_a, apart_b = _box((10, 10, 10)), _box((10, 10, 10), (14.0, 0.0, 0.0))
    plate_holes = [(x, y, 25.4) for x in (-60.0, 0.0, 60.0) for y in (-100.0, 0.0, 100.0)]
    return [
        ("rod_5x5x61", "5 x 5 x 61 mm square rod (12 diameters)", _box((5, 5, 61)), "mm", _box_release((5, 5, 61))),
        ("rod_d3_L45", "3 mm x 45 mm 64-gon rod (15 diameters)", rod_cyl, "mm", _prism_release(1.5, 64, 45.0)),
        ("rod_d1_L20", "1 mm x 20 mm 32-gon pin (20 diameters)", trimesh.creation.cylinder(radius=0.5, height=20.0,
                                                                                          sections=32),
         "mm", _prism_release(0.5, 32, 20.0)),
        ("plate_203x305", "203 x 305 x 12.7 mm plate, nine 1 in holes",
         _drilled(_box((203.0, 305.0, 12.7)), plate_holes, 12.7), "mm", None),
        ("plate_1mm", "60 x 40 x 1 mm plate, four 5 mm holes",
         _drilled(_box((60.0, 40.0, 1.0)), [(x, y, 5.0) for x in (-20, 20) for y in (-10, 10)], 1.0), "mm", None),
        ("box_open", "50 x 40 x 30 mm open box, 1.5 mm walls", _open_box((50.0, 40.0, 30.0), 1.5), "mm", None),
        ("box_sealed", "40 x 30 x 20 mm closed box, 2 mm walls (sealed void)", sealed, "mm", sealed_exact),
        ("bracket_in", "angle bracket drawn in inches (--units in)", _bracket_in(), "in", None),
        ("l_bodies_in", "an L of two bars drawn in inches whose corner edges coincide (--units in)",
         trimesh.util.concatenate([_box((2.0, 0.25, 1.0)), _box((0.25, 1.5, 1.0), (-0.875, 0.625, 0.0))]), "in", None),
        ("torus", "torus R 20, r 3 mm", torus, "mm",
         lambda t: torus.volume - 2 * np.pi ** 2 * 20.0 * np.clip(r - np.asarray(t), 0, None) ** 2),
        ("torus_fat", "torus R 8, r 3 mm", analytic.torus()[0], "mm", analytic.torus()[2]),
        ("sphere_void", "ball r 10 mm, sealed void r 3 mm off-centre", hollow, "mm", hollow_exact),
        ("two_touching", "10 mm cube with a 6 mm cube set on it (touching)",
         trimesh.util.concatenate([stacked_a, stacked_b]), "mm", None),
        ("two_overlapping", "two 10 mm cubes overlapping by 4 mm", trimesh.util.concatenate([cube_a, cube_b]), "mm",
         _box_release((16, 10, 10))),
        ("two_apart", "two 10 mm cubes 4 mm apart", trimesh.util.concatenate([apart_a, apart_b]), "mm",
         lambda t: 2 * _box_release((10, 10, 10))(t)),
        ("cube_10", "10 mm cube", _box((10, 10, 10)), "mm", _box_release((10, 10, 10))),
        ("cylinder_2x8", "2 mm x 8 mm 64-gon cylinder", trimesh.creation.cylinder(radius=1.0, height=8.0, sections=64),
         "mm", _prism_release(1.0, 64, 8.0)),
        ("sphere_r10", "ball r 10 mm (icosphere)", sphere, "mm", sphere_exact),
        ("sphere_r1", "ball r 1 mm (2 mm across)", trimesh.creation.icosphere(subdivisions=4, radius=1.0), "mm", None),
    ]


def _grown_box_release(dims, o: float) -> Callable[[np.ndarray], np.ndarray]:
    """A box grown by o > 0 (isotropic): the shell first (Steiner's volume V(o) - V(o - tau)), then the box shrunk."""
    dims = np.asarray(dims, float)

    def steiner(r):
        return (np.prod(dims) + 2 * (dims[0] * dims[1] + dims[1] * dims[2] + dims[0] * dims[2]) * r
                + np.pi * dims.sum() * r ** 2 + 4 * np.pi / 3 * r ** 3)

    def exact(t):
        t = np.asarray(t, float)
        inner = np.prod(np.clip(dims - 2 * (t - o)[:, None], 0, None), axis=1)
        return np.where(t < o, steiner(o) - steiner(np.clip(o - t, 0, None)), steiner(o) - inner)

    return exact


def _shrunk_box_release(dims, o: float, a: float) -> Callable[[np.ndarray], np.ndarray]:
    """A box shrunk by |o| released at anisotropy a: its metric copy (z / a) shrinking by tau, volumes times a."""
    metric = (np.asarray(dims, float) + 2 * o) / np.array([1.0, 1.0, a])
    return lambda t: a * (np.prod(metric) - np.prod(np.clip(metric - 2 * np.asarray(t)[:, None], 0, None), axis=1))


def print_parts() -> list[tuple[str, str, trimesh.Trimesh, dict, Callable | None]]:
    """(name, what, mesh, print physics, exact release in mm or None for Sobol with T = s + o)."""
    torus = trimesh.creation.torus(major_radius=20.0, minor_radius=3.0, major_sections=256, minor_sections=64)
    plate = _drilled(_box((60.0, 40.0, 1.0)), [(x, y, 5.0) for x in (-20, 20) for y in (-10, 10)], 1.0)

    def physics(o, a=1.0):
        return {"anisotropy": a, "offset_mm": o, "swelling_mm": 0.0}

    return [
        ("rod_5x5x61+0.1", "5 x 5 x 61 mm rod grown 0.1 mm", _box((5, 5, 61)), physics(0.1),
         _grown_box_release((5, 5, 61), 0.1)),
        ("cube_10-0.2_a0.7", "10 mm cube shrunk 0.2 mm, anisotropy 0.7", _box((10, 10, 10)), physics(-0.2, 0.7),
         _shrunk_box_release((10, 10, 10), -0.2, 0.7)),
        ("plate_1mm-0.1", "60 x 40 x 1 mm plate with holes shrunk 0.1 mm", plate, physics(-0.1), None),
        ("sphere_r10+0.2", "ball r 10 mm grown 0.2 mm", analytic.sphere()[0], physics(0.2), None),
        ("torus+0.15", "torus R 20, r 3 mm grown 0.15 mm", torus, physics(0.15), None),
    ]


def sobol_print_release(mesh: trimesh.Trimesh, offset_mm: float) -> Callable[[np.ndarray], np.ndarray]:
    """released(tau) of a mesh's print {s > -o} with T = s + o, from 2^SOBOL_LOG2 quasi-random points' exact signed
    distances s in the print's bounding box; its volume the points' share of the box."""
    from scipy.stats import qmc

    from design.forward.distance import Surface

    grow = max(offset_mm, 0.0)
    lo, hi = mesh.bounds[0] - grow, mesh.bounds[1] + grow
    points = lo + (hi - lo) * qmc.Sobol(d=3, scramble=True, seed=7).random_base2(SOBOL_LOG2)
    arrive = Surface(mesh).signed_distance(points)[0] + offset_mm
    depth = np.sort(arrive[arrive > 0])
    volume = float(np.prod(hi - lo)) * depth.size / len(points)
    return lambda t: volume * np.searchsorted(depth, np.asarray(t), side="right") / depth.size


def run_print(root: Path, part: Path, out: Path, physics: dict) -> tuple[dict, np.ndarray, float, float]:
    """``labapp.jobs.simulate.simulate(part, out, physics=physics)`` of the checkout ``root`` as a child, at its
    default model; (summary, release.csv rows, wall s, CPU s)."""
    code = ("import json, sys; from labapp.jobs.simulate import simulate; "
            "simulate(sys.argv[1], sys.argv[2], physics=json.loads(sys.argv[3]))")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    done = subprocess.run([str(root / ".venv" / "bin" / "python"), "-c", code, str(part), str(out),
                           json.dumps(physics)], cwd=root, capture_output=True, text=True, timeout=1800)
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        return {"failed": done.stderr.strip().splitlines()[-1]}, np.zeros((0, 2)), wall, cpu
    curve = np.loadtxt(out / "release.csv", delimiter=",", skiprows=1, usecols=(0, 1))
    return json.loads((out / "summary.json").read_text()), curve, wall, cpu


def main_prints(args: argparse.Namespace, work: Path) -> None:
    """The ``--prints`` table: each print part by both checkouts' default model against its exact release."""
    print("| print | exact by | after: RMS / max / end, % | after: wall / CPU s | after: method | "
          "before: RMS / max / end, % | before: wall / CPU s | before: model |")
    print("|---|---|---|---|---|---|---|---|")
    for name, what, mesh, physics, exact in print_parts():
        if args.only and name not in args.only:
            continue
        path = work / f"{name}.stl"
        mesh.export(path)
        if exact is None:
            exact, how = sobol_print_release(trimesh.load_mesh(path), physics["offset_mm"]), f"Sobol 2^{SOBOL_LOG2}"
        else:
            how = "analytic"
        volume = float(exact(np.array([1e3]))[0])
        cells = []
        for label, root in (("after", args.after), ("before", args.before)):
            out = Path(tempfile.mkdtemp(prefix=f"{name}_{label}_", dir=work)) / "sim"
            summary, curve, wall, cpu = run_print(root, path, out, physics)
            errs = "-" if not len(curve) else " / ".join(f"{e:.2f}" for e in errors(curve, exact, volume))
            cells += [errs, f"{wall:.1f} / {cpu:.1f}", _how(summary)]
        print(f"| {name}: {what} | {how} | " + " | ".join(cells) + " |", flush=True)


def _solid_mm(path: Path, units: str) -> trimesh.Trimesh:
    """The solid the file describes, in mm: bodies that touch or overlap united (as ``sfr simulate`` reads it)."""
    from design.files.meshio import load_mesh

    return load_mesh(path, MM_PER_UNIT[units])


def sobol_release(mesh: trimesh.Trimesh) -> Callable[[np.ndarray], np.ndarray]:
    """released(tau) of a solid whose shells all face the bath, from 2^SOBOL_LOG2 quasi-random points' exact
    distances to its surface."""
    from scipy.stats import qmc

    from design.forward.distance import Surface

    lo, hi = mesh.bounds
    points = lo + (hi - lo) * qmc.Sobol(d=3, scramble=True, seed=7).random_base2(SOBOL_LOG2)
    surface = Surface(mesh)
    signed = surface.signed_distance(points)[0]
    _check_brute_force(mesh, points[:: len(points) // 200], signed[:: len(points) // 200])
    depth = np.sort(signed[signed > 0])
    volume = float(mesh.volume)
    return lambda t: volume * np.searchsorted(depth, np.asarray(t), side="right") / depth.size


def _check_brute_force(mesh: trimesh.Trimesh, points: np.ndarray, signed: np.ndarray) -> None:
    """The hierarchy's distances against every triangle's (trimesh's closest point on each triangle)."""
    tri = mesh.triangles
    for p, s in zip(points, signed):
        q = trimesh.triangles.closest_point(tri, np.repeat(p[None, :], len(tri), axis=0))
        d = float(np.sqrt(((q - p) ** 2).sum(axis=1)).min())
        if abs(abs(s) - d) > 1e-9 * max(1.0, d):
            raise AssertionError(f"distance {s} != brute force {d} at {p}")


def run(sfr: Path, cwd: Path, part: Path, out: Path, units: str) -> tuple[dict, np.ndarray, float, float]:
    """Run ``sfr simulate`` as a child; (summary, release.csv rows, wall s, CPU s)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    cmd = [str(sfr), "simulate", str(part), "--out", str(out)] + (["--units", units] if units != "mm" else [])
    done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=1800)
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        return {"failed": done.stderr.strip().splitlines()[-1]}, np.zeros((0, 2)), wall, cpu
    curve = np.loadtxt(out / "release.csv", delimiter=",", skiprows=1, usecols=(0, 1))
    return json.loads((out / "summary.json").read_text()), curve, wall, cpu


def errors(curve: np.ndarray, exact: Callable, volume: float) -> tuple[float, float, float]:
    """RMS and max |released - exact| over the curve's samples, and the final value's error, % of the volume."""
    diff = curve[:, 1] - exact(curve[:, 0])
    return (100 * float(np.sqrt(np.mean(diff ** 2))) / volume, 100 * float(np.abs(diff).max()) / volume,
            100 * (float(curve[-1, 1]) / volume - 1.0))


def _how(summary: dict) -> str:
    if "failed" in summary:
        return f"refused: {summary['failed'][:90]}"
    if summary.get("model") == "exact":
        reason = summary["lattice"]["reason"]
        passes = (reason.split("(lattice ")[-1].split(" of")[0] if "(lattice " in reason
                  else "best of " + reason.split("the best of ")[-1].split(" lattices")[0] + ", over the aim")
        return (f"exact, h {summary['lattice']['spacing_mm']:.3g} mm (lattice {passes}), "
                f"stated {100 * summary['error']['error_fraction']:.2f}%")
    return f"grid {summary.get('voxels', 0):,} voxels of {summary.get('voxel_size_mm', 0):.3g} mm" + (
        "" if summary.get("error", {}).get("error_fraction") is None else
        f", stated {100 * summary['error']['error_fraction']:.2f}%")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, default=Path("/work/base"), help="checkout of the BEFORE baseline")
    parser.add_argument("--after", type=Path, default=Path(__file__).resolve().parents[1], help="checkout measured")
    parser.add_argument("--only", nargs="*", help="part names")
    parser.add_argument("--work", type=Path, help="folder for the parts and runs (default: a temporary one)")
    parser.add_argument("--prints", action="store_true", help="the parts printed with a surface offset instead")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="hard_parts_"))
    if args.prints:
        main_prints(args, work)
        return
    print("| part | exact by | after: RMS / max / end, % | after: wall / CPU s | after: method, lattice | "
          "before: RMS / max / end, % | before: wall / CPU s | before: grid |")
    print("|---|---|---|---|---|---|---|---|")
    for name, what, mesh, units, exact in parts():
        if args.only and name not in args.only:
            continue
        path = work / f"{name}.stl"
        mesh.export(path)
        solid = _solid_mm(path, units)
        if exact is None:
            exact, how = sobol_release(solid), f"Sobol 2^{SOBOL_LOG2}"
        else:
            how = "analytic"
        volume = float(solid.volume)
        cells = []
        for label, root in (("after", args.after), ("before", args.before)):
            out = Path(tempfile.mkdtemp(prefix=f"{name}_{label}_", dir=work)) / "sim"
            summary, curve, wall, cpu = run(root / ".venv" / "bin" / "sfr", root, path, out, units)
            errs = "-" if not len(curve) else " / ".join(f"{e:.2f}" for e in errors(curve, exact, volume))
            cells += [errs, f"{wall:.1f} / {cpu:.1f}", _how(summary)]
        print(f"| {name}: {what} | {how} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
