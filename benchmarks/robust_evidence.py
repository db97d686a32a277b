"""Default-flag designs of the shipped samples and of `benchmarks/robust_sources.py`, in both spaces.

Runs ``sfr design --target T --space S --resolution R --max-iter N --out DIR`` for every source and
space (nothing else set: default flags), with this tree's code and, with ``--prev PATH`` (a checkout of
an earlier commit), with that code too; skips runs whose folder already holds a summary, so an
interrupted sweep resumes. Prints one markdown row per source and space, with the earlier code's
figures beside the new ones.

    python benchmarks/robust_evidence.py OUT_DIR [--resolution 128] [--max-iter 300] [--prev /tmp/prev]
        [--spaces extruded nfc]

Last line: ``rows: <count>``.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.robust_sources import BUILDERS, EXTRUSIONS, source  # noqa: E402
from design.files.records import load_summary  # noqa: E402
from design.geometry.shapes import SAMPLE_SHAPES  # noqa: E402


def _run(code_root: Path, target: str, space: str, resolution: int, max_iter: int, out: Path) -> dict | None:
    if not (out / "summary.json").exists():
        env = dict(os.environ, PYTHONPATH=str(code_root))
        cmd = [sys.executable, "-m", "labapp.cli.main", "design", "--target", target, "--space", space,
               "--resolution", str(resolution), "--max-iter", str(max_iter), "--out", str(out)]
        proc = subprocess.run(cmd, env=env, cwd="/tmp", capture_output=True, text=True)
        if proc.returncode != 0 or not (out / "summary.json").exists():
            print(f"failed: {' '.join(cmd)}\n{proc.stderr[-2000:]}", file=sys.stderr)
            return None
    return load_summary(out)


def _cell(s: dict | None) -> str:
    return "-" if s is None else f"{s['rel_rmse_design_grid_binary']:.2%} / {s['pieces']}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--max-iter", type=int, default=300)
    parser.add_argument("--prev", type=Path, help="checkout of the earlier code to compare with")
    parser.add_argument("--spaces", nargs="+", default=["extruded", "nfc"])
    args = parser.parse_args()
    src_dir = args.out_dir / "sources"
    src_dir.mkdir(parents=True, exist_ok=True)
    targets = {name: name for name in SAMPLE_SHAPES}
    for name in BUILDERS:
        path = src_dir / f"{name}.stl"
        if not path.exists():
            source(name).export(path)
        targets[name] = str(path)
    print("| source | extrusion | space | binary fit / pieces, earlier code | binary fit / pieces, this code "
          "| s/eval (this code) |")
    print("|---|---|---|---|---|---|")
    rows = 0
    for space in args.spaces:
        for name, target in targets.items():
            tag = f"{name}_{space}_{args.resolution}"
            new = _run(ROOT, target, space, args.resolution, args.max_iter, args.out_dir / "new" / tag)
            prev = (_run(args.prev, target, space, args.resolution, args.max_iter, args.out_dir / "prev" / tag)
                    if args.prev else None)
            extrusion = "yes" if name in EXTRUSIONS else "no"  # no shipped sample is one
            speed = "-" if new is None else f"{new['seconds_per_iteration'] or 0:.3f}"
            print(f"| {name} | {extrusion} | {space} | {_cell(prev)} | {_cell(new)} | {speed} |", flush=True)
            rows += 1
    print(f"rows: {rows}")


if __name__ == "__main__":
    main()
