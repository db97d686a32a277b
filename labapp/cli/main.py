"""The `sfr` command line: one subcommand per module in `labapp.cli.commands`.

Each command module defines ``NAME`` (the subcommand), ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Heavy imports belong inside
``run`` so that ``sfr --help`` stays instant.

Errors are mapped to exit codes in one place, :func:`exit_code`: 0 success, 1 the job failed, 2 bad
input or usage (argparse's own errors are 2 as well), 130 interrupted with Ctrl-C or SIGTERM. A command
raises; :func:`main` prints one line on stderr (``--debug``, before or after the command, adds the
traceback). While a command runs, Ctrl-C and SIGTERM are recorded, not raised (:mod:`labapp.cli.interrupt`):
the command stops at its next safe point and :func:`main` ends with one ``interrupted: ...`` line. A command
module that handles signals itself (the GUI) sets ``SIGNALS = False``.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys
import traceback

from labapp.cli import commands, interrupt
from labapp.cli.operator import add_operator_option
from labapp.errors import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, LabError
from labapp.records.fileio import disk_error

#: The commands in the order of a lab's workflow (bench set-up, measurement, simulation and design,
#: then the tools); commands not named here are listed after them, alphabetically.
WORKFLOW = ("devices", "calibrate-bench", "run", "change", "verify", "analyze", "calibrate-sim", "simulate", "design",
            "sweep", "compare", "lab", "demo", "emulate")
FINISHED_WHEN_INTERRUPTED = "the command had finished its work when the signal came; its outputs are complete"


def _command_modules() -> list:
    modules = [importlib.import_module(f"{commands.__name__}.{info.name}")
               for info in pkgutil.iter_modules(commands.__path__) if not info.name.startswith("_")]
    rank = {name: i for i, name in enumerate(WORKFLOW)}
    return sorted(modules, key=lambda m: (rank.get(m.NAME, len(WORKFLOW)), m.NAME))


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("shape-from-release")
    except PackageNotFoundError:
        return "unknown (not installed)"


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line usage error (exit code 2) that points to ``--help``."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: {message} ('{self.prog} --help' lists the options)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full `sfr` argument parser with every discovered subcommand, in workflow order."""
    parser = _Parser(prog="sfr", description="Shape from Release: measure, simulate and design release.",
                                     epilog="exit codes: 0 success, 1 the job failed, 2 bad input or usage, "
                                            "130 interrupted")
    parser.add_argument("--version", action="version", version=f"sfr {_version()}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error")
    # the same two options after the command (sfr design --debug ...); SUPPRESS keeps the value given before it
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="log debug messages")
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show the traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in _command_modules():
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP, parents=[common])
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _signals=getattr(module, "SIGNALS", True))
        if getattr(module, "RECORDS", False):
            add_operator_option(p, module.run, module.RECORDS)
    return parser


def command_list() -> str:
    """``sfr`` with no arguments: the commands in workflow order, one line each."""
    lines = [f"sfr {_version()}: measure, simulate and design release. Commands, in workflow order:"]
    mods = _command_modules()
    width = max(len(m.NAME) for m in mods)
    lines += [f"  {m.NAME:<{width}}  {m.HELP}" for m in mods]
    lines.append("'sfr COMMAND --help' for its options; 'sfr --version'; exit codes: 0 success, 1 the job failed, "
                 "2 bad input or usage")
    return "\n".join(lines)


def exit_code(exc: BaseException) -> int:
    """The exit code for an error that ended a command (the one mapping of errors to exit codes).

    2 (bad input or usage): :class:`labapp.errors.UsageError`, ``design.DesignError`` and
    ``analysis.AnalysisError`` (their messages name the input at fault), ``ValueError`` from a settings
    check, a missing input file, an output on a full, read-only or forbidden disk
    (:data:`labapp.records.fileio.OUT_ERRNOS`, also behind another error it caused).
    130: ``KeyboardInterrupt``. 1 (the job failed): every other error, device errors included.
    """
    from analysis import AnalysisError
    from design.errors import DesignError

    if isinstance(exc, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if isinstance(exc, LabError):
        return exc.exit_code
    if isinstance(exc, (DesignError, AnalysisError, ValueError, FileNotFoundError, NotADirectoryError)):
        return EXIT_USAGE
    if disk_error(exc) is not None:
        return EXIT_USAGE
    return EXIT_FAILED


def error_line(exc: BaseException, out: str | None = None) -> str:
    """One line for the operator: the message, whitespace collapsed; an unexpected error names its type; a full or
    read-only disk names the file (or the command's ``--out``, ``out``, when the error does not)."""
    from analysis import AnalysisError
    from design.errors import DesignError
    from drivers.errors import DriverError

    text = " ".join(str(exc).split()) or type(exc).__name__
    expected = (LabError, DesignError, AnalysisError, DriverError, ValueError, OSError)
    # an OSError, or an unexpected error a full disk caused (a compressor failing after its write did); the
    # package errors name the file themselves
    disk = disk_error(exc) if isinstance(exc, OSError) or not isinstance(exc, expected) else None
    if disk is not None:
        where = disk.filename or (out if out else "its output")
        return f"cannot write {where}: {disk.strerror or os.strerror(disk.errno)}" + \
            ("" if disk.filename else "; free space or choose a writable --out")
    if not isinstance(exc, expected):
        return f"internal error ({type(exc).__name__}: {text}); rerun with --debug for the traceback"
    return text


def _quiet_stdout() -> None:
    """After a broken pipe (``sfr ... | head``): send what is still buffered to /dev/null."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def _run_command(args: argparse.Namespace) -> int:
    """Run the parsed command; 130 with one ``interrupted: ...`` line if Ctrl-C or SIGTERM came."""
    if not args._signals:
        with interrupt.suspended():
            return int(args._run(args) or 0)
    interrupt.check()   # a signal during start-up: stop before the command begins
    code = int(args._run(args) or 0)
    if interrupt.requested():   # 130 from the command: it stopped early; else it had finished all the same
        sys.stdout.flush()
        print(f"interrupted: {interrupt.hint() if code == EXIT_INTERRUPTED else FINISHED_WHEN_INTERRUPTED}",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    return code


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `sfr` console script; returns the process exit code.

    Ctrl-C and SIGTERM are recorded from here on (:mod:`labapp.cli.interrupt`), also while the commands load;
    called with ``argv`` (in-process, e.g. from tests) the previous handlers are restored on return.
    """
    interrupt.reset()
    if argv is None:    # the process's own command line: signals stay recorded until the process has exited
        interrupt.install()
        try:
            return _main(sys.argv[1:])
        finally:
            interrupt.ignore_while_exiting()
    with interrupt.handling():
        return _main(list(argv))


def _main(argv: list[str]) -> int:
    args = None
    try:
        if not argv:
            print(command_list())
            code = EXIT_OK
        else:
            args = build_parser().parse_args(argv)
            logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                                format="%(levelname)s %(name)s: %(message)s")
            code = _run_command(args)
        sys.stdout.flush()      # a reader that closed early (head) is noticed here, not at interpreter exit
        return code
    except KeyboardInterrupt:
        print(f"interrupted: {interrupt.hint()}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_OK
    except SystemExit:
        raise
    except Exception as exc:
        if getattr(args, "debug", False) or "--debug" in argv:
            traceback.print_exc()
        command = next((a for a in argv if not a.startswith("-")), "")
        out = getattr(args, "out", None)
        print(f"sfr {command}: {error_line(exc, out if isinstance(out, str) else None)}".replace("sfr : ", "sfr: "),
              file=sys.stderr)
        if interrupt.requested():   # the error ended a command that was being stopped: it is still an interruption
            print(f"interrupted: {interrupt.hint()}", file=sys.stderr)
            return EXIT_INTERRUPTED
        return exit_code(exc)


if __name__ == "__main__":
    sys.exit(main())
