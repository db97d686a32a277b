"""`sfr sweep`: a grid of design settings for one target, each combination an `sfr design` run folder,
on a local Dask cluster or an existing scheduler (docs/scale.md)."""
from __future__ import annotations

import argparse
import sys

from labapp.cli import interrupt
from labapp.cli.argtypes import positive_int
from labapp.cli.eta import eta_text
from labapp.errors import EXIT_INTERRUPTED

NAME = "sweep"
HELP = "run a grid of design settings (TOML spec) on a local Dask cluster or a scheduler; sweep.csv + contact sheet"
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr sweep`."""
    parser.add_argument("spec", help="sweep spec, TOML: target, fixed settings, [grid] lists, [[points]] (docs/scale.md)")
    parser.add_argument("--out", required=True, help="sweep folder (a rerun skips finished combinations and resumes "
                                                      "the others)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="tcp://HOST:PORT of a running Dask scheduler "
                                                               "(default: a local cluster on this machine)")
    parser.add_argument("--workers", type=positive_int, metavar="N",
                        help="local cluster: worker processes (default: one per core, as many as memory holds); "
                             "with --scheduler: wait for N workers before starting")


def progress_printer():
    """Progress on stderr: one rewritten line on a terminal, else a line whenever the counts change."""
    tty, last = sys.stderr.isatty(), [None]

    def show(p) -> None:
        counts = (p.done, p.failed, p.running, p.left)
        line = (f"{p.done} done ({p.failed} failed), {p.running} running, {p.left} left, {eta_text(p.eta_s)}")
        if tty:
            print("\r" + line + "   ", end="", file=sys.stderr, flush=True)
        elif counts != last[0]:
            print(line, file=sys.stderr, flush=True)
        last[0] = counts
    return show


def run(args: argparse.Namespace) -> int:
    """Check the spec and --out, start or join the cluster, run the sweep, print where the results are."""
    from labapp.records.lock import folder_lock
    from labapp.scaleout.sweep import sweep_on_cluster
    from labapp.scaleout.sweepspec import load_spec

    spec = load_spec(args.spec)
    where = args.scheduler or "a local cluster"

    def started(start) -> None:
        print(f"sweep of {len(spec.combinations)} combinations into {start.sweep_dir} on {where} "
              f"({start.workers} workers, ~{start.task_memory_gb:.2f} GB per design)", file=sys.stderr)
        if start.dashboard:
            print(f"Dask dashboard: {start.dashboard}", file=sys.stderr)
    interrupt.set_hint(f"running designs were checkpointed in {args.out}; rerun the same command to resume")
    with folder_lock(args.out), interrupt.handling(on_second=interrupt.raise_now):
        result = sweep_on_cluster(spec, args.out, scheduler=args.scheduler, workers=args.workers, on_start=started,
                                  on_progress=progress_printer(), should_stop=interrupt.requested)
    out = result.table.parent
    if sys.stderr.isatty():
        print(file=sys.stderr)
    for name in result.failed:
        print(f"failed: {name} (see {out / 'failed' / (name + '.txt')})", file=sys.stderr)
    print(f"wrote {result.table}" + (f", {result.contact_sheet}" if result.contact_sheet else ""))
    if result.stopped:
        return EXIT_INTERRUPTED
    return 1 if result.failed else 0
