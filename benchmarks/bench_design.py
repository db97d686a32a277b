"""Seconds per iteration of inverse design against one scikit-fmm forward solve on the same grid, and the
cost of a design's other stages (its correction rounds' print checks and its outputs), each on its own line.

Iterations. For each reduced grid N^3 (nfc, octant symmetry: the full design is (2N)^3) this runs the design
optimiser (`design.inverse.optimize.optimise`, default optimiser, checkpoints written by the run folder's
`design.files.rundir.CheckpointFile`) on a zero-order target in a 20 mm cube, with a fixed objective, eq. (4)
plus J_rate (r = 4 voxels, no connectivity term, no physical correction), so that the ratio does not move with
the design defaults; nothing after the optimiser (correction rounds, outputs) runs in this part. After a
warm-up (the L-BFGS memory fills; its step cost grows with the stored pairs), it alternates, for ``--rounds``
rounds, a block of design iterations (one checkpoint interval, so every block holds one checkpoint) with a
block of first-order `skfmm.travel_time` solves of the design's current density on the same N^3 grid, from
inside the optimiser's progress callback. Each round's ratio compares the two blocks measured within the same
minute, so a slow period of the machine (other jobs) slows both; the headline is the median ratio over the
rounds, printed with its spread.

An iteration is the wall time between two progress callbacks (objective, gradient, optimiser step,
bookkeeping and checkpoint). Its breakdown: "objective" is `DesignObjective.evaluate` less its
adjoint chain; "gradient" is that adjoint chain (release-curve VJP, projection and filter adjoints);
"optimiser" is `Lbfgs.tell` (for nlopt, the rest of the iteration after everything else);
"checkpoint" is the run's wait for `_Run.checkpoint` (starting it, and waiting for the thread that
writes it while the next evaluation runs); "bookkeeping" what remains (cosine map, history); "writer"
is that thread's own time, overlapped with the evaluations, not part of the sum.

Stages. A default-settings design of a source shape (the pill, one start, ``STAGE_EVALS`` evaluations with its
two correction rounds) at full resolution 2N runs through `design.files.rundir.run_design`; the lines give
its seconds per evaluation, each print check of the correction rounds (`design.inverse.defect.check_print`:
the extraction and the reference evaluator's release of the print) and the outputs
(`design.files.outputs.write_outputs`). Peak memory is the process's maximum resident set size.

    python -m benchmarks.bench_design [--quick] [--rounds R] [--optimizer NAME]

Last line: ``iter_over_skfmm_128: <median ratio>`` (``iter_over_skfmm_64`` with --quick).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import tempfile
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np
import skfmm

import design.files.rundir
import design.inverse.defect
import design.inverse.objective
import design.inverse.optimize
from design.files.rundir import CheckpointFile, run_design
from design.inverse.config import DesignConfig
from design.inverse.filters import SmoothingFilter
from design.inverse.lbfgs import Lbfgs
from design.inverse.objective import DesignObjective
from design.inverse.optimize import build_objective, optimise
from design.inverse.problem import prepare

ROUNDS = 5
"""Alternating rounds per grid by default: the machine's speed can drift by a fifth from minute to minute, and the median
of five rounds is not one slow minute's."""
PARTS = ("evaluate", "gradient", "optimiser", "checkpoint", "writer")
STAGE_EVALS = 80
"""Evaluations of the stages' design (64 of the optimisation, two correction rounds of 8): enough for a solid to
extract and judge."""


def skfmm_seconds(rho: np.ndarray, dx_mm: float) -> float:
    """Wall time of one first-order scikit-fmm travel-time solve through density ``rho``, s."""
    phi = np.pad(np.ones(rho.shape), 1, constant_values=-1.0)  # front on the padding layer
    speed = np.pad(1.0 / (rho + (1.0 - rho) * 1e-6), 1, constant_values=1.0)
    t0 = time.perf_counter()
    skfmm.travel_time(phi, speed, dx=dx_mm, order=1)
    return time.perf_counter() - t0


@contextmanager
def _timed(owner: object, name: str, totals: dict[str, float], part: str, keep: dict | None = None):
    """Replace ``owner.name`` by a wrapper adding its wall time to ``totals[part]``; ``keep`` gets
    the last (instance, result) of a method."""
    original = getattr(owner, name)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        result = original(*args, **kwargs)
        totals[part] += time.perf_counter() - t0
        if keep is not None:
            keep["result"] = result
        return result

    setattr(owner, name, wrapper)
    try:
        yield
    finally:
        setattr(owner, name, original)


def bench(n_reduced: int, warmup: int, rounds: int, block: int, solves: int, optimizer: str) -> dict:
    """One grid size: per-round seconds per iteration, its breakdown, skfmm seconds and their ratio."""
    config = DesignConfig(target="zero-order:final=0.15,duration=0.2", space="nfc", resolution=2 * n_reduced,
                          domain_mm=(20.0, 20.0, 20.0), max_iter=warmup + rounds * block, checkpoint_every=block,
                          optimizer=optimizer, radius_vox=4.0, allow_pieces=True, beta_final=3.0,  # one stage
                          starts=1, robust_eta=0.0, physical_correction="none")  # one simulation per evaluation
    totals = dict.fromkeys(PARTS, 0.0)
    last: dict = {}
    marks: dict = {"out": None, "iter": 0.0, "n": 0, "parts": dict(totals)}
    per_round: list[dict] = []

    def on_iteration(k: int, x, terms) -> None:
        now = time.perf_counter()
        if k > warmup:
            marks["iter"] += now - marks["out"]
            marks["n"] += 1
        if k >= warmup and (k - warmup) % block == 0:
            if k > warmup:  # end of a round's design block: its skfmm block
                load = os.getloadavg()[0]
                rho = np.asarray(last["result"].rho)
                base = float(np.median([skfmm_seconds(rho, problem.dx_mm) for _ in range(solves)]))
                parts = {p: (totals[p] - marks["parts"][p]) / marks["n"] for p in PARTS}
                per_round.append({"seconds_per_iteration": marks["iter"] / marks["n"], "skfmm_seconds": base,
                                  "load_before": marks["load"], "load_after": load, **parts})
            marks.update(iter=0.0, n=0, parts=dict(totals), load=os.getloadavg()[0])
        marks["out"] = time.perf_counter()

    problem = prepare(config)
    objective = build_objective(problem, config)
    with tempfile.TemporaryDirectory() as tmp, ExitStack() as patches:
        patches.enter_context(_timed(DesignObjective, "evaluate", totals, "evaluate", last))
        for name in ("release_gradient", "project_adjoint"):
            patches.enter_context(_timed(design.inverse.objective, name, totals, "gradient"))
        patches.enter_context(_timed(SmoothingFilter, "adjoint", totals, "gradient"))
        patches.enter_context(_timed(Lbfgs, "tell", totals, "optimiser"))
        patches.enter_context(_timed(design.inverse.optimize._Run, "checkpoint", totals, "checkpoint"))
        patches.enter_context(_timed(CheckpointFile, "wait", totals, "checkpoint"))
        patches.enter_context(_timed(design.files.rundir, "save_checkpoint", totals, "writer"))
        store = CheckpointFile(Path(tmp) / "checkpoint.npz")
        optimise(objective, problem, config, store, on_iteration=on_iteration)
        store.wait()
    for r in per_round:
        r["objective"] = r.pop("evaluate") - r["gradient"]
        if optimizer != "lbfgs":  # nlopt's step is not visible: it is the remainder
            r["optimiser"] = r["seconds_per_iteration"] - r["objective"] - r["gradient"] - r["checkpoint"]
        r["bookkeeping"] = (r["seconds_per_iteration"] - r["objective"] - r["gradient"] - r["optimiser"]
                            - r["checkpoint"])
        r["ratio"] = r["seconds_per_iteration"] / r["skfmm_seconds"]
    ratios = [r["ratio"] for r in per_round]
    return {"n_reduced": n_reduced, "full": 2 * n_reduced, "optimizer": optimizer, "warmup": warmup, "block": block,
            "rounds": per_round, "ratio_median": float(np.median(ratios)), "ratio_min": min(ratios),
            "ratio_max": max(ratios), "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2}


def stages(resolution: int) -> dict:
    """A default design of the pill at ``resolution`` (`STAGE_EVALS` evaluations, one start): seconds per
    evaluation, per print check of its correction rounds, and of its outputs, with the CPU time of each."""
    config = DesignConfig(target="pill", resolution=resolution, max_iter=STAGE_EVALS, starts=1)
    wall = {"checks": 0.0, "outputs": 0.0}
    cpu = dict(wall)
    calls = {"checks": 0}

    def clocked(owner, name: str, part: str):
        original = getattr(owner, name)

        def wrapper(*args, **kwargs):
            w0, c0 = time.perf_counter(), time.process_time()
            result = original(*args, **kwargs)
            wall[part] += time.perf_counter() - w0
            cpu[part] += time.process_time() - c0
            calls[part] = calls.get(part, 0) + 1
            return result

        setattr(owner, name, wrapper)
        return original

    kept = [(design.inverse.defect, "check_print", clocked(design.inverse.defect, "check_print", "checks")),
            (design.files.rundir, "write_outputs", clocked(design.files.rundir, "write_outputs", "outputs"))]
    load = os.getloadavg()[0]
    w0, c0 = time.perf_counter(), time.process_time()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            result = run_design(config, Path(tmp) / "run")
    finally:
        for owner, name, original in kept:
            setattr(owner, name, original)
    total_wall, total_cpu = time.perf_counter() - w0, time.process_time() - c0
    evals_wall = total_wall - wall["checks"] - wall["outputs"]
    evals_cpu = total_cpu - cpu["checks"] - cpu["outputs"]
    return {"resolution": resolution, "evaluations": result.iterations, "load": load,
            "seconds_per_evaluation": evals_wall / result.iterations, "cpu_per_evaluation": evals_cpu / result.iterations,
            "print_checks": calls["checks"], "seconds_per_print_check": wall["checks"] / max(calls["checks"], 1),
            "cpu_per_print_check": cpu["checks"] / max(calls["checks"], 1),
            "outputs_seconds": wall["outputs"], "outputs_cpu": cpu["outputs"],
            "rel_rmse_print": result.outputs.summary["rel_rmse_print"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="64^3 only, short rounds; stages at 64")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help=f"alternating rounds per grid (>= 3, default {ROUNDS})")
    parser.add_argument("--optimizer", default=DesignConfig.optimizer, help="design optimiser (default: the default)")
    args = parser.parse_args()
    if args.rounds < 3:
        parser.error("--rounds must be at least 3 for a median with a spread")
    # warm-up: the default L-BFGS memory (10 pairs) is full after ~11 evaluations
    sizes = [(64, 4, 3)] if args.quick else [(64, 12, 10), (128, 12, 10)]
    solves = {64: 5, 128: 3}
    t0 = time.perf_counter()
    print(f"load average at start: {os.getloadavg()}")
    results = [bench(n, warmup, args.rounds, block, solves[n], args.optimizer) for n, warmup, block in sizes]
    stage = stages(64 if args.quick else 128)
    for r in results:
        print(json.dumps(r))
    print(json.dumps(stage))
    for r in results:
        print(f"{r['n_reduced']}^3 reduced ({r['full']}^3 full), {r['optimizer']}, {len(r['rounds'])} rounds of "
              f"{r['block']} iterations after {r['warmup']}, peak RSS {r['peak_rss_gb']:.2f} GB")
        print("  round  s/iter  objective  gradient  optimiser  checkpoint  bookkeeping  (writer)  skfmm  ratio  load")
        for i, q in enumerate(r["rounds"], 1):
            print(f"  {i:5d}  {q['seconds_per_iteration']:.3f}  {q['objective']:9.3f}  {q['gradient']:8.3f}  "
                  f"{q['optimiser']:9.3f}  {q['checkpoint']:10.3f}  {q['bookkeeping']:11.3f}  {q['writer']:8.3f}  "
                  f"{q['skfmm_seconds']:.3f}  {q['ratio']:.3f}  {q['load_before']:.2f}-{q['load_after']:.2f}")
        print(f"  ratio median {r['ratio_median']:.3f} (spread {r['ratio_min']:.3f}-{r['ratio_max']:.3f})")
    print(f"stages of a default pill design at {stage['resolution']} ({stage['evaluations']} evaluations, "
          f"load {stage['load']:.2f}): wall (CPU) s")
    print(f"  evaluation    {stage['seconds_per_evaluation']:.3f} ({stage['cpu_per_evaluation']:.3f}) each")
    print(f"  print check   {stage['seconds_per_print_check']:.3f} ({stage['cpu_per_print_check']:.3f}) each, "
          f"{stage['print_checks']} in the correction rounds")
    print(f"  outputs       {stage['outputs_seconds']:.3f} ({stage['outputs_cpu']:.3f})")
    print(f"benchmark wall time {time.perf_counter() - t0:.0f} s")
    last = results[-1]
    print(f"iter_over_skfmm_{last['n_reduced']}: {last['ratio_median']:.3f}")


if __name__ == "__main__":
    main()
