"""Write docs/results_samples.md: what `sfr design` achieves on the shipped samples with its defaults.

    .venv/bin/python -m studies.results_page [--quick] [--out PAGE] [--keep DIR]

Runs every case of `CASES` through `labapp.jobs.design.design`, the job `sfr design` calls, with
`design.inverse.config.DesignConfig`'s defaults for everything but the target, the design space and
the resolution, and once more without the physical correction (``physical_correction="none"``), and writes a
Markdown page: the software versions, the defaults used (read from `DesignConfig` and from each case's resolved
configuration, never restated here), one table row per case, the print's true fit (``rel_rmse_print``, by the
reference evaluator) beside the design grid's before and after the correction, and a figure of the release curves.
``--quick`` runs the same cases at `QUICK_RESOLUTION` (a smoke test of several minutes) and prints the page
instead of writing it unless ``--out`` is given.

Progress goes to stderr. Ctrl-C stops the running design at its next evaluation, writes nothing and
exits with 130 (a second Ctrl-C leaves at once). The design run folders go to a temporary folder,
or to ``--keep DIR``. Last line: ``cases: <count>, <minutes> min``.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import signal
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from design.files.summary_text import percent_text

ROOT = Path(__file__).resolve().parents[1]
RESOLUTION = 64
"""Voxels along the longest side of every case's design domain (full page)."""
QUICK_RESOLUTION = 32
"""The same with ``--quick``."""
PROGRESS_EVERY = 50
"""Evaluations between progress lines on a non-terminal stderr."""


@dataclass(frozen=True)
class Case:
    """One design of the page: a target spec of `sfr design --target` and a design space."""

    target: str
    space: str
    label: str


_TARGETS = (("sphere", "sample"), ("pill", "sample"), ("spinner_top", "sample"), ("csg", "sample"),
            ("polyhedron", "sample"), ("zero-order", "analytic"), ("accel:q=2", "analytic"),
            ("accel:q=0.5", "analytic"))
CASES = tuple(Case(target, space, f"`{target}` ({kind})") for target, kind in _TARGETS for space in ("nfc", "extruded"))
"""The five shipped sample shapes as mesh targets (their simulated release) and three analytic targets
with their default final amount and duration (constant, accelerating and decelerating release), each
in the free 3D space (nfc) and in the extruded space (prints without supports). The ico space is left
out: its elasticity solves make a design several times costlier (docs/benchmarks.md)."""
WARM_UP = Case("sphere", "nfc", "warm-up")
"""A tiny design run before the cases, so that no case's seconds include compiling the kernels."""

RESOLVED_FIELDS = ("w_binary", "radius", "beta", "beta_final", "w_rate", "robust_eta", "w_connect", "starts")
"""Settings whose default depends on the space or the target: shown per case."""


def _config(case: Case, resolution: int):
    from design.inverse.config import DesignConfig

    return DesignConfig(target=case.target, space=case.space, resolution=resolution)


def _resolved(config) -> dict[str, str]:
    """The space- and target-dependent settings a case ran with, as text."""
    from design.inverse.settings import DEFAULT_RADIUS_MM

    radius = (f"{config.radius_vox:g} vox" if config.radius_vox is not None
              else f"{config.radius_mm if config.radius_mm is not None else DEFAULT_RADIUS_MM:g} mm")
    values = {f: getattr(config, f) for f in RESOLVED_FIELDS if f != "radius"}
    values["radius"] = radius
    return {f: values[f] if isinstance(values[f], str) else f"{values[f]:g}" for f in RESOLVED_FIELDS}


def _shared_defaults() -> list[tuple[str, str]]:
    """`DesignConfig` fields with a fixed default: (name, value); per-case ones are marked."""
    from design.inverse.config import DesignConfig

    rows = []
    for f in dataclasses.fields(DesignConfig):
        if f.default is dataclasses.MISSING or f.name in ("resolution", "space"):
            continue
        if f.name in RESOLVED_FIELDS + ("radius_vox", "radius_mm"):
            value = "per case (below)"
        elif f.default is None:
            value = "not set (derived from the target and space)"
        else:
            value = f"`{f.default!r}`"
        rows.append((f.name, value))
    return rows


class _Stop:
    """Ctrl-C sets the flag the running design polls; a second Ctrl-C raises KeyboardInterrupt."""

    def __init__(self) -> None:
        self.event = threading.Event()

    def __call__(self, signum, frame) -> None:
        if self.event.is_set():
            raise KeyboardInterrupt
        self.event.set()
        print("\nstopping at the next evaluation (Ctrl-C again to leave at once) ...", file=sys.stderr, flush=True)


def _progress(prefix: str, max_iter: int):
    tty = sys.stderr.isatty()

    def show(k: int, x, terms: dict) -> None:
        if not tty and k % PROGRESS_EVERY and k < max_iter:
            return
        phase = f"{terms['phase']} " if "phase" in terms else ""
        line = f"{prefix} {phase}evaluation {k}/{max_iter}, J {terms['J']:.4g}, {terms['seconds']:.0f} s"
        print(("\r" + line + "   ") if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
    return show


BEFORE, AFTER = "none", None
"""The two runs of each case: without the physical correction (``physical_correction="none"``, before) and with
`DesignConfig`'s default (after)."""


def run_case(case: Case, resolution: int, folder: Path, stop: _Stop, prefix: str,
             correction: str | None = AFTER) -> dict:
    """Design one case into ``folder`` (``correction``: `DesignConfig.physical_correction`, None = its default);
    returns its row of figures (``status`` "stopped" when interrupted)."""
    from design.errors import DesignError
    from labapp.jobs.design import design

    config = dataclasses.replace(_config(case, resolution), physical_correction=correction)
    start = time.perf_counter()
    try:
        result, _ = design(config, folder, on_iteration=_progress(prefix, config.max_iter),
                           should_stop=stop.event.is_set,
                           on_warning=lambda message: print(f"\n{prefix} warning: {message}", file=sys.stderr))
    except DesignError as exc:   # e.g. a target that is infeasible on this grid: refused, as sfr design does
        return dict(case=case, config=config, status="refused", error=" ".join(str(exc).split()),
                    wall=time.perf_counter() - start)
    wall = time.perf_counter() - start
    if sys.stderr.isatty():
        print(file=sys.stderr)
    s = result.outputs.summary
    return dict(case=case, config=config, status=result.status, iterations=result.iterations,
                density=s["rel_rmse_density"], binary=s["rel_rmse_design_grid_binary"], true=s["rel_rmse_print"],
                true_error=s["rel_rmse_print_error"], pieces=s["pieces"], mass_g=s["print_mass_g"],
                voids=s["enclosed_voids"], rate_dev=s["rate_dev_mid80_vs_target"]["print"], seconds=s["seconds"],
                wall=wall, software=s["software"], folder=result.out_dir, warnings=s["warnings"])


def _warm_up(folder: Path, stop: _Stop) -> None:
    """Compile the kernels on a tiny design (not reported)."""
    from labapp.jobs.design import design

    print("warm-up: compiling the kernels on a tiny design ...", file=sys.stderr, flush=True)
    config = dataclasses.replace(_config(WARM_UP, 16), max_iter=3)
    design(config, folder, should_stop=stop.event.is_set, on_warning=lambda message: None)


def _zero_order(case: Case) -> bool:
    return case.target.partition(":")[0] == "zero-order"


def _machine() -> str:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} cores{', ' + model if model else ''}, {platform.system()} {platform.machine()}"


def figure(rows: list[dict], path: Path) -> None:
    """One panel per case: the target and the printed solid's release on the design grid and by the reference evaluator."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    cols = 4
    nrows = -(-len(rows) // cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.2 * nrows), squeeze=False)
    rows = [r for r in rows if "folder" in r]
    for ax, row in zip(axes.flat, rows):
        data = np.genfromtxt(row["folder"] / "curves.csv", delimiter=",", names=True)
        ax.plot(data["tau_mm"], data["target_mm3"], color="k", lw=2, label="target (physical)")
        ax.plot(data["tau_mm"], data["binary_mm3"], "--", color="C1", label="printed solid, design grid")
        if np.all(np.isfinite(data["print_mm3"])):
            ax.plot(data["tau_mm"], data["print_mm3"], color="C3", lw=1.2, label="printed solid (reference)")
        ax.set_title(f"{row['case'].target}, {row['case'].space}: {percent_text(row['true'])}", fontsize=9)
        final = data["target_mm3"][-1]
        ax.set_xlim(0, 1.3 * data["tau_mm"][np.argmax(data["target_mm3"] >= 0.999 * final)])
        ax.set_xlabel("tau (mm dissolved)")
        ax.set_ylabel("released (mm$^3$)")
    for ax in list(axes.flat)[len(rows):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _before_after(rows: list[dict], before: dict) -> list[str]:
    """The table of true fits beside design-grid fits, without and with the physical correction."""
    lines = [
        "## The print's true fit, before and after the physical correction",
        "",
        "Each case designed twice, with `--physical-correction none` (before: the design grid's release alone) and",
        "with the default (after: the defect-correction rounds of `design.inverse.defect`, within the same",
        "evaluations); [design.md](design.md#physical-correction) says how they work. The **true** fit is the",
        "printed solid's (`design.stl`) release against the target's physical release, both by the reference",
        "evaluator (`design.forward.reference`: exact surface distances); the design-grid fit is the printed",
        "solid re-voxelised on the design grid against the target there (`rel_rmse_design_grid_binary`).",
        "",
        "| case | space | design grid, before | **true, before** | design grid, after | **true, after** "
        "| pieces, before / after | seconds, before / after |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        b = before.get((r["case"].target, r["case"].space))
        if b is None or "folder" not in r or "folder" not in b:
            continue
        lines.append(f"| {r['case'].label} | {r['case'].space} | {percent_text(b['binary'])} | "
                     f"**{percent_text(b['true'])}** | {percent_text(r['binary'])} | **{percent_text(r['true'])}** | "
                     f"{b['pieces']} / {r['pieces']} | {b['wall']:.0f} / {r['wall']:.0f} |")
    return lines + [""]


COLUMN_NOTES = [
    "How to read the columns (all in `summary.json` of the run folder; formats: [formats.md](formats.md)):",
    "",
    "- **rel. RMSE** is the RMS difference of two release curves over the target's tau grid, divided by",
    "  the target's final release.",
    "- **density (design grid)**: the optimised grey density's simulated release against the target on",
    "  the grid the optimiser worked on (`rel_rmse_density`). A diagnostic of the optimisation only: the",
    "  density is not what is printed.",
    "- **printed solid (design grid)**: the printed mesh (`design.stl`, the contour that keeps the",
    "  density's mass) re-voxelised on the design grid and simulated (`rel_rmse_design_grid_binary`, the figure the",
    "  paper plots). A diagnostic too: on the design grid the voxelisation error of the grid itself, which",
    "  the optimiser has learnt to use, is part of both curves.",
    "- **printed solid (true)**: `design.stl`'s release by the reference evaluator (exact surface distances,",
    "  `design.forward.reference`) against the target's physical release (a sample shape's by the same",
    "  evaluator, an analytic target's curve as it is; `rel_rmse_print`, with its stated error): what the",
    "  print does, and the figure to judge a design by.",
    "- **rate deviation** (zero-order targets): the largest deviation of the printed solid's release rate",
    "  from the target's constant rate over the target's middle 80% (10% to 90% released), in 20 equal",
    "  windows, of the printed solid's reference release (`rate_dev_mid80_vs_target`, `design.inverse.rate`).",
    "- **pieces**: separate solid parts of the printed solid (1 = one printable piece). **enclosed voids**:",
    "  voids the bath cannot reach until a wall dissolves. **seconds**: wall time of the whole job,",
    "  output writing included (the kernels are compiled before the first case).",
]
"""The page's notes on its results table."""


def _result_row(r: dict) -> str:
    """One case's row of the results table (a case that failed: its status and error)."""
    if "folder" not in r:
        return (f"| {r['case'].label} | {r['case'].space} | - | {r['status']}: "
                f"{r['error']} | - | - | - | - | - | - | - | {r['wall']:.0f} |")
    return (f"| {r['case'].label} | {r['case'].space} | {r['iterations']} | "
            f"{r['status']} | {percent_text(r['density'])} | {percent_text(r['binary'])} | "
            f"**{percent_text(r['true'])}** (± {percent_text(r['true_error'])}) | "
            f"{percent_text(r['rate_dev']) if _zero_order(r['case']) else '-'} | "
            f"{r['pieces']} | {r['mass_g']:.3f} | {r['voids']} | {r['wall']:.0f} |")


def page(rows: list[dict], resolution: int, minutes: float, figure_name: str | None, quick: bool,
         before: dict | None = None) -> str:
    """The Markdown of the page (``before``: the runs without the physical correction, by (target, space))."""
    from design.files.outputs import software_versions

    done = [r for r in rows if "folder" in r]
    software = done[0]["software"] if done else software_versions()
    lines = [
        "# Inverse design: what `sfr design` achieves with its defaults",
        "",
        "Written by `studies/results_page.py`; do not edit by hand. Regenerate after any change to the",
        "design code or its defaults:",
        "",
        "```bash",
        ".venv/bin/python -m studies.results_page            # writes this page and its figure",
        ".venv/bin/python -m studies.results_page --quick    # the same cases at resolution "
        f"{QUICK_RESOLUTION}, printed",
        "```",
        "",
        f"Every case is `sfr design --target TARGET --space SPACE --resolution {resolution}` with nothing else",
        "set: the job `sfr design` calls (`labapp.jobs.design.design`), with the defaults of",
        "`design.inverse.config.DesignConfig`. What each flag means: [guide.md](guide.md#design-a-shape-from-a-"
        "target-release).",
        "",
        "## Software and machine",
        "",
        "| | version |",
        "|---|---|",
        *[f"| {name} | {version or 'not installed'} |" for name, version in software.items()],
        f"| machine | {_machine()} |",
        "",
        f"The full page took {minutes:.1f} min of wall time on this machine, one case after another.",
        "",
        "## Results (with the defaults)",
        "",
        "| case | space | evaluations | status | rel. RMSE, density (design grid) | rel. RMSE, printed solid "
        "(design grid) | **rel. RMSE, printed solid (true)** | rate deviation (true) | pieces | print mass (g) "
        "| enclosed voids | seconds |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [_result_row(r) for r in rows]
    lines += [
        "",
        *COLUMN_NOTES,
        "",
    ]
    if before:
        lines += _before_after(rows, before)
    warned = [(r, w) for r in rows for w in r.get("warnings", ())]
    if warned:
        lines += ["What the runs warned about (`warnings` in `summary.json`, also printed by `sfr design`):", ""]
        lines += [f"- {r['case'].label}, {r['case'].space}: {w}" for r, w in warned]
        lines.append("")
    if figure_name:
        lines += [f"![release curves of every case]({figure_name})", ""]
    lines += [
        "## Defaults used",
        "",
        f"Settings of every case (the `DesignConfig` defaults; `resolution` is the page's {resolution}):",
        "",
        "| setting | default |",
        "|---|---|",
        *[f"| `{name}` | {value} |" for name, value in _shared_defaults()],
        "",
        "Settings whose default depends on the design space or the target, as each case resolved them:",
        "",
        "| case | " + " | ".join(f"`{f}`" for f in RESOLVED_FIELDS) + " |",
        "|---|" + "---|" * len(RESOLVED_FIELDS),
        *[f"| {r['case'].label}, {r['case'].space} | " + " | ".join(_resolved(r["config"]).values()) + " |"
          for r in rows],
        "",
        "Why the defaults are what they are: [design.md](design.md).",
    ]
    if quick:
        lines[0] += " (quick run)"
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=f"resolution {QUICK_RESOLUTION}; print the page")
    parser.add_argument("--out", type=Path, help="page to write (default docs/results_samples.md; with --quick: print)")
    parser.add_argument("--keep", type=Path, help="keep the design run folders in this new folder")
    args = parser.parse_args(argv)
    out = args.out or (None if args.quick else ROOT / "docs" / "results_samples.md")
    resolution = QUICK_RESOLUTION if args.quick else RESOLUTION
    if args.keep is not None and args.keep.exists():
        parser.error(f"--keep {args.keep} exists; name a new folder")
    stop = _Stop()
    signal.signal(signal.SIGINT, stop)
    begin = time.perf_counter()
    rows: list[dict] = []
    before: dict[tuple[str, str], dict] = {}
    with tempfile.TemporaryDirectory(prefix="results_page_") as tmp:
        runs = args.keep or Path(tmp)
        runs.mkdir(parents=True, exist_ok=True)
        try:
            _warm_up(runs / "warm-up", stop)
            for i, case in enumerate(CASES, 1):
                prefix = f"[{i}/{len(CASES)}] {case.target} {case.space}:"
                print(f"{prefix} designing at resolution {resolution} ...", file=sys.stderr, flush=True)
                plain = run_case(case, resolution, runs / f"{case.target}_{case.space}_none", stop,
                                 prefix + " (no correction)", BEFORE)
                row = plain if stop.event.is_set() else run_case(case, resolution, runs / f"{case.target}_{case.space}",
                                                                  stop, prefix)
                if stop.event.is_set() or {plain["status"], row["status"]} & {"stopped", "interrupted"}:
                    print("stopped: no page written", file=sys.stderr)
                    return 130
                before[(case.target, case.space)] = plain
                rows.append(row)
                if "folder" not in row:
                    print(f"{prefix} {row['status']}: {row['error']}", file=sys.stderr, flush=True)
                    continue
                print(f"{prefix} {row['status']} after {row['iterations']} evaluations, {row['wall']:.0f} s; "
                      f"printed solid {percent_text(row['binary'])} (design grid), {percent_text(row['true'])} (true; "
                      f"{percent_text(plain.get('true'))} without correction), {row['pieces']} piece(s)",
                      file=sys.stderr, flush=True)
        except KeyboardInterrupt:
            print("\ninterrupted: no page written", file=sys.stderr)
            return 130
        minutes = (time.perf_counter() - begin) / 60.0
        figure_name = None
        if out is not None:
            figures = out.parent / "figures"
            figures.mkdir(parents=True, exist_ok=True)
            figure_name = f"figures/{out.stem}_cases.png"
            figure(rows, out.parent / figure_name)
        text = page(rows, resolution, minutes, figure_name, args.quick, before)
        if out is None:
            print(text)
        else:
            out.write_text(text)
            print(f"wrote {out} and {out.parent / figure_name}", file=sys.stderr)
    print(f"cases: {len(rows)}, {minutes:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
