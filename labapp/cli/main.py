"""The `sfr` command line: one subcommand per module in `labapp.cli.commands`.

Each command module defines ``NAME`` (the subcommand), ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Heavy imports belong inside
``run`` so that ``sfr --help`` stays instant.

Errors are mapped to exit codes in one place, :func:`exit_code`: 0 success, 1 the job failed, 2 bad
input or usage (argparse's own errors are 2 as well), 130 interrupted with Ctrl-C. A command raises;
:func:`main` prints one line on stderr (``--debug`` adds the traceback).
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys
import traceback

from labapp.cli import commands
from labapp.cli.operator import add_operator_option
from labapp.errors import EXIT_FAILED, EXIT_OK, EXIT_USAGE, LabError

#: The commands in the order of a lab's workflow (bench set-up, measurement, simulation and design,
#: then the tools); commands not named here are listed after them, alphabetically.
WORKFLOW = ("devices", "calibrate-bench", "run", "verify", "analyze", "calibrate-sim", "simulate", "design",
            "sweep", "compare", "lab", "demo", "emulate")
EXIT_INTERRUPTED = 130


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
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in _command_modules():
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
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
    check, a missing input file. 1 (the job failed): every other error, device errors included.
    """
    from analysis import AnalysisError
    from design.errors import DesignError

    if isinstance(exc, LabError):
        return exc.exit_code
    if isinstance(exc, (DesignError, AnalysisError, ValueError, FileNotFoundError, NotADirectoryError)):
        return EXIT_USAGE
    return EXIT_FAILED


def error_line(exc: BaseException) -> str:
    """One line for the operator: the message, whitespace collapsed; an unexpected error names its type."""
    from analysis import AnalysisError
    from design.errors import DesignError
    from drivers.errors import DriverError

    text = " ".join(str(exc).split()) or type(exc).__name__
    expected = (LabError, DesignError, AnalysisError, DriverError, ValueError, OSError)
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


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `sfr` console script; returns the process exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        if not argv:
            print(command_list())
            code = EXIT_OK
        else:
            args = build_parser().parse_args(argv)
            logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                                format="%(levelname)s %(name)s: %(message)s")
            code = int(args._run(args) or 0)
        sys.stdout.flush()      # a reader that closed early (head) is noticed here, not at interpreter exit
        return code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_OK
    except SystemExit:
        raise
    except Exception as exc:
        if "--debug" in argv:
            traceback.print_exc()
        command = next((a for a in argv if not a.startswith("-")), "")
        print(f"sfr {command}: {error_line(exc)}".replace("sfr : ", "sfr: "), file=sys.stderr)
        return exit_code(exc)


if __name__ == "__main__":
    sys.exit(main())
