"""`sfr design --target T --barrier-speed S`: the two-material option and its run (a drug and a barrier)."""
from __future__ import annotations

import argparse
import sys

from labapp.cli.argtypes import nonnegative_float

TAKEN = {"space": "space", "resolution": "resolution", "domain_mm": "domain_mm", "height_mm": "height_mm",
         "radius_mm": "radius_mm", "max_iter": "max_iter", "beta": "beta", "beta_final": "beta_final",
         "w_binary": "w_binary"}
"""The `sfr design` settings a two-material design takes: setting -> `TwoMaterialSettings` field."""


CALIBRATED = "calibrated"
"""``--barrier-speed`` without a number (or with this word): the --simcal calibration's barrier speed."""


def _barrier_speed(text: str) -> float | str:
    """A barrier speed >= 0, or the word ``calibrated``."""
    return CALIBRATED if text == CALIBRATED else nonnegative_float(text)


def add_barrier_design_arguments(parser: argparse.ArgumentParser) -> None:
    """The two-material option of `sfr design`."""
    group = parser.add_argument_group("two materials (a drug and a placebo barrier)")
    group.add_argument("--barrier-speed", type=_barrier_speed, metavar="S", nargs="?", const=CALIBRATED,
                       help="design a drug and a barrier eroding at S times the drug's rate (0: insoluble), in nfc or "
                            "extruded; without S: the --simcal calibration's barrier speed (fitted from coated prints); "
                            "--target: delay-zero:delay=D,rate=R,volume=V, pulses:volume=V,width=W,gap=G, "
                            "constant:rate=R,volume=V (mm, mm^3), a tau_mm,released_mm3 CSV or, with --simcal, a measured "
                            "curve (a run folder or a t_s,released_g CSV); writes design.stl (drug), barrier.stl and "
                            "design.3mf (both)")


def wants_barrier_design(args: argparse.Namespace) -> bool:
    """Whether `sfr design` runs a two-material design: ``--barrier-speed`` given, or ``--resume`` of a two-material
    run's folder."""
    if args.barrier_speed is not None:
        return True
    if not args.resume:
        return False
    from design.files.twomaterial_run import is_two_material_run

    return is_two_material_run(args.out)


def _settings_options(args: argparse.Namespace, given: dict) -> dict:
    """The given design settings as `TwoMaterialSettings` fields; refuses the ones a two-material design does not take."""
    from labapp.errors import UsageError

    refused = [name for name in given if name != "target" and name not in TAKEN]
    refused += [flag for flag, value in (("--simcal", args.resume and args.simcal),
                                         ("--calibration", args.resume and args.calibration), ("--units", args.units))
                if value]
    if refused:
        raise UsageError(f"--barrier-speed does not take {', '.join(sorted(refused))}: a two-material design takes "
                         "--space (nfc, extruded), --resolution, --domain-mm, --height, --radius-mm, --max-iter, --beta, "
                         "--beta-final, --w-binary, and --simcal and --calibration when it starts")
    options = {TAKEN[k]: v for k, v in given.items() if k in TAKEN}
    if "domain_mm" in options:
        x, y, z = options["domain_mm"]
        if not x == y or (options.get("space", "nfc") == "nfc" and not x == z):
            raise UsageError(f"--domain-mm {x:g} {y:g} {z:g}: a two-material domain is square in x, y (and cubic for "
                             "nfc); give equal sizes (the extrusion height is --height)")
        options["domain_mm"] = float(x)
    if options.get("space") == "ico":
        raise UsageError("--space ico with --barrier-speed: the ICO term models one material's stiffness, and no "
                         "stiffness law for a drug/barrier pair is calibrated; use --space nfc or extruded")
    return options


def _progress(max_iter: int):
    tty = sys.stderr.isatty()

    def show(k: int, terms: dict) -> None:
        from labapp.cli import interrupt

        interrupt.check()
        if not tty and k % 10 and k < max_iter:
            return
        line = (f"stage {terms['stage']} (beta {terms['beta']:.3g}): it {k:4d}/{max_iter}  J {terms['J']:.5g}  "
                f"fit {terms['rel_rmse']:.2%}  binary {terms['J_binary']:.3g}  {terms['seconds']:.0f}s")
        print(("\r" + line + "   ") if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
    return show


def summary_text(s: dict, out) -> list[str]:
    """What the command prints about a finished two-material design."""
    b = s["barrier"]
    lines = [f"two-material design ({s['space']}, barrier speed {s['barrier_speed']:g}): {s['status']} after "
             f"{s['evaluations']} evaluations, {s['seconds']:.0f} s -> {out}",
             f"  drug {s['drug']['volume_mm3']:.2f} mm^3 (design.stl), barrier {b['volume_mm3']:.2f} mm^3 (barrier.stl), "
             f"both in design.3mf",
             f"  fit (relative RMS): density {s['density_fit']:.2%}, print on the design grid {s['grid_fit']:.2%}"
             + (f", print by the reference evaluator {s['reference_fit']:.2%}" if s["reference_fit"] is not None else
                f" (reference evaluator: {s['reference']})"),
             f"  pieces: print {s['print_pieces']}, drug {s['drug']['pieces']}, barrier {b['pieces']}",
             "  thinnest barrier wall in front of covered drug: "
             + ("none (no covered drug)" if b["min_wall_mm"] is None else f"{b['min_wall_mm']:.3g} mm")
             + f" (at least {b['min_wall_required_mm']:g} mm)"
             + (f"; {s['thickened_voxels']} drug voxels made barrier to reach it" if s["thickened_voxels"] else "")
             + (f"; {b['thin_mm3']:.3g} mm^3 of barrier elsewhere is thinner (rims, fins)" if b.get("thin_mm3") else ""),
             f"  barrier cover {b['cover_mm']:.3g} mm: "
             + ("release starts at tau = 0" if b["release_starts_mm"] == 0.0 else "drug sealed" if b["release_starts_mm"]
                is None else f"release starts at tau = {b['release_starts_mm']:.3g} mm")]
    lines += [f"  note: {n}" for n in s["piece_notes"]]
    return lines


def run_barrier_design(args: argparse.Namespace, given: dict) -> int:
    """Run `sfr design` given ``--barrier-speed``: check the options, design, print the summary."""
    from labapp.cli import interrupt
    from labapp.jobs.design_barrier import design_barrier
    from labapp.jobs.design_barrier_measured import design_barrier_measured, write_physical

    options = _settings_options(args, given)
    settings, simcal, source = _start(args, options)
    interrupt.set_hint(f"the best design so far is saved in {args.out}; resume with: sfr design --resume --out {args.out}")
    max_iter = settings.max_iter if settings else options.get("max_iter", 0)
    try:
        if settings is not None and simcal is not None and _is_measured(args.target):
            from analysis import BenchCalibration

            bench = BenchCalibration.load(args.calibration) if args.calibration else None
            result = design_barrier_measured(settings, args.out, simcal, bench_calibration=bench, speed_source=source,
                                             on_iteration=_progress(max_iter))
        else:
            given = options if args.barrier_speed is None else dict(options, barrier_speed=args.barrier_speed)
            result = design_barrier(settings, args.out, resume=args.resume, options=given,
                                    on_iteration=_progress(max_iter))
    finally:
        print(file=sys.stderr)
    if result.summary is None:
        print(f"stopped: resume with sfr design --resume --out {args.out}")
        return 130
    if result.unchanged:
        print(f"already finished: nothing to do ({result.out} is left as it is)")
    for line in summary_text(result.summary, result.out):
        print(line)
    physical = write_physical(result.out) if not result.unchanged else None
    if physical is not None:
        print(f"  measured target: the print's predicted release is {physical['rel_rmse_physical']:.2%} RMS of the "
              f"measured final release off the measured curve (curves_physical.csv; barrier speed "
              f"{physical['barrier_speed']:.4g}, {physical['speed_source']})")
    return 0


def _is_measured(target: str) -> bool:
    from labapp.jobs.physical import is_physical

    return is_physical(target)


def _start(args: argparse.Namespace, options: dict):
    """The settings of a new run (None for a resume), its calibration (None without --simcal) and where its barrier
    speed came from (``given`` or ``calibrated``)."""
    from design.inverse.twomaterial_problem import TwoMaterialSettings
    from labapp.errors import UsageError
    from labapp.jobs.design_barrier_measured import barrier_speed_of
    from labapp.records.simcal import load_simcal

    if args.resume:
        if args.barrier_speed == CALIBRATED:
            raise UsageError("--barrier-speed without a number takes the --simcal calibration's speed when a run starts; "
                             "drop it to resume")
        return None, None, "given"
    if not args.target:
        raise UsageError("--target is required (unless --resume)")
    simcal = load_simcal(args.simcal) if args.simcal else None
    speed, source = args.barrier_speed, "given"
    if speed == CALIBRATED:
        if simcal is None:
            raise UsageError("--barrier-speed without a number takes the barrier speed of the --simcal calibration; "
                             "give --simcal SIMCAL.json (calibrated with coated prints) or a speed")
        speed, source = barrier_speed_of(simcal)[0], "calibrated"
    if simcal is None and _is_measured(args.target):
        raise UsageError(f"--target {args.target} is a measured curve (grams over seconds): give --simcal SIMCAL.json to "
                         "map it to simulation units")
    if args.calibration and not (simcal is not None and _is_measured(args.target)):
        raise UsageError("--calibration with --barrier-speed analyses a measured run-folder target; give one with --simcal")
    return TwoMaterialSettings(args.target, speed, **options), simcal, source
