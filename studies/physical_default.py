"""Default designs of untuned shapes (benchmarks/untuned_shapes.py) and the true fit of their prints, one CSV row each.

Each design is `design.files.rundir.run_design` with `DesignConfig`'s defaults for the shape's mesh, the space and
the resolution (resumed when its folder already holds a run). A row: the print's true fit (``rel_rmse_print`` of
``summary.json``) and the same figure recomputed here from ``design.stl`` and the source mesh by the reference
evaluator (`design.forward.reference`, its default lattice), the design grid's fit, pieces, seconds, evaluations and
the print's fit after each correction round (``rounds.npz``), and the physical correction it ran with.

    python -m studies.physical_default OUT_CSV RUNS_DIR SHAPE:SPACE [SHAPE:SPACE ...] [--resolution 128]
        [--correction none]
    python -m studies.physical_default OUT_CSV --table

``--correction none``: the same designs without the physical correction (``--physical-correction none``, the
"before"), in folders named ``<shape>_<space>_<resolution>_none``. Last line: ``rows: <count>``. ``--table``
prints the CSV as the Markdown table of docs/results.md (the default designs, with the same shape's run without
the correction beside it where there is one).
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
import trimesh

from benchmarks import untuned_shapes


def design_row(name: str, space: str, resolution: int, runs: Path, correction: str | None = None) -> dict:
    from design.files.rundir import run_design
    from design.forward.reference import reference_release
    from design.inverse.config import DesignConfig
    from design.inverse.objective import rel_rmse

    folder = runs / (f"{name}_{space}_{resolution}" + ("" if correction is None else f"_{correction}"))
    stl = runs / f"{name}.stl"
    untuned_shapes.source(name).export(stl)
    resume = (folder / "config.json").exists()
    t0 = time.perf_counter()
    extra = {} if correction is None else {"physical_correction": correction}
    result = run_design(None if resume else DesignConfig(target=str(stl), space=space, resolution=resolution, **extra),
                        folder, resume=resume)
    wall = time.perf_counter() - t0
    s = result.outputs.summary
    tau = np.genfromtxt(folder / "curves.csv", delimiter=",", names=True)["tau_mm"]
    goal = reference_release(trimesh.load_mesh(stl), tau).released_mm3
    again = rel_rmse(reference_release(trimesh.load_mesh(folder / "design.stl"), tau).released_mm3, goal)
    fits = ""
    if (folder / "rounds.npz").exists():
        with np.load(folder / "rounds.npz") as rounds:
            fits = ";".join(f"{100 * f:.3f}" for f in rounds["fits"])
    summary_fit = s.get("rel_rmse_print")  # None in a summary written before it was recorded
    grid_fit = s.get("rel_rmse_design_grid_binary", s.get("rel_rmse_binary"))
    return {"shape": name, "space": space, "resolution": resolution,
            "true_fit": "-" if summary_fit is None else f"{100 * summary_fit:.4f}",
            "recomputed": f"{100 * again:.4f}", "grid_fit": "-" if grid_fit is None else f"{100 * grid_fit:.4f}",
            "pieces": s["pieces"], "seconds": f"{s['seconds']:.0f}", "wall": f"{wall:.0f}",
            "iterations": s["iterations"], "round_fits": fits, "correction": correction or "defect"}


def append_row(path: Path, row: dict) -> None:
    """Append ``row`` to the CSV at ``path``, with a header line when the file is new."""
    new = not path.exists()
    with path.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, list(row))
        if new:
            writer.writeheader()
        writer.writerow(row)


def _pct(value: str) -> str:
    return "-" if value in ("", "-", None) else f"{float(value):.2f}%"


def table(path: Path) -> str:
    """The CSV's rows as Markdown: a line per shape, space and resolution; the default run's print (true fit) and
    design-grid fits, and the same figures of the run without the correction where the CSV has one."""
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    cases: dict[tuple[str, str, str], dict[str, dict]] = {}
    for r in rows:  # a later row of the same case replaces an earlier one (a resumed or repeated run)
        cases.setdefault((r["shape"], r["space"], r["resolution"]), {})[r.get("correction") or "defect"] = r
    lines = ["| shape | space | resolution | **true fit, default** | design grid, default | true fit, `none` | "
             "design grid, `none` | pieces | print after each round | seconds |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for (name, space, resolution), runs in cases.items():
        d, n = runs.get("defect", {}), runs.get("none", {})
        kind = " (extrusion)" if name in untuned_shapes.EXTRUSIONS else ""
        true = d.get("true_fit") if d.get("true_fit") not in (None, "", "-") else d.get("recomputed")
        pieces = " / ".join(x["pieces"] for x in (d, n) if x)
        seconds = " / ".join(x["seconds"] for x in (d, n) if x)
        rounds = ", ".join(f"{float(f):.2f}" for f in d.get("round_fits", "").split(";") if f) or "-"
        lines.append(f"| {name}{kind} | {space} | {resolution} | **{_pct(true)}** | {_pct(d.get('grid_fit'))} | "
                     f"{_pct(n.get('recomputed'))} | {_pct(n.get('grid_fit'))} | {pieces} | {rounds} | {seconds} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv", type=Path)
    parser.add_argument("runs", type=Path, nargs="?")
    parser.add_argument("cases", nargs="*", metavar="SHAPE:SPACE")
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--correction", choices=("none",), help="run without the physical correction")
    parser.add_argument("--table", action="store_true", help="print the CSV as a Markdown table")
    args = parser.parse_args()
    if args.table:
        print(table(args.csv))
        return
    if args.runs is None or not args.cases:
        parser.error("RUNS_DIR and at least one SHAPE:SPACE are needed (or --table)")
    args.runs.mkdir(parents=True, exist_ok=True)
    for case in args.cases:
        name, _, space = case.partition(":")
        row = design_row(name, space, args.resolution, args.runs, args.correction)
        append_row(args.csv, row)
        print(",".join(str(v) for v in row.values()), flush=True)
    with args.csv.open() as handle:
        print(f"rows: {sum(1 for _ in handle) - 1}")


if __name__ == "__main__":
    main()
