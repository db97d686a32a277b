"""A warmed `sfr` for tests that start many short commands: one process imports the jobs and runs each command
once, then forks a child per command, so each command starts in milliseconds instead of paying the imports.

A child runs :func:`labapp.cli.main.main` as ``python -m labapp.cli.main`` would, in its own process with its
own signal handling, its standard output and error in files. The protocol is one JSON object per line:

    stdin  {"warm": [[ARG, ...], ...], "cwd": DIR}    stdout {"warmed": true}
    stdin  {"run": [ARG, ...], "cwd": DIR, "log": PREFIX}  stdout {"pid": PID}   (PREFIX.out, PREFIX.err)
    stdin  {"poll": PID}                               stdout {"code": EXIT CODE, or null while it runs}
 The commands' own output during the warm-up goes to the
server's standard error.

A child that ends with an exception escaping ``main`` exits with 99 and the traceback in its error file.

    python tests/labapp/cli/warm_cli.py
"""
from __future__ import annotations

import contextlib
import json
import os
import sys
import threading
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
ESCAPED = 99


def _child(args: list[str], cwd: str, log: str) -> None:
    """In the forked child: the command with its outputs in files; never returns."""
    code = ESCAPED
    try:
        os.chdir(cwd)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        for fd, suffix in ((1, ".out"), (2, ".err")):
            os.dup2(os.open(log + suffix, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644), fd)
        from labapp.cli.main import main

        try:
            code = main(args)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:
        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _warm(commands: list[list[str]], cwd: str) -> None:
    """Run each command once in this process: the imports and the compiled code stay for every child."""
    from labapp.cli.main import main

    os.chdir(cwd)
    for args in commands:
        with contextlib.redirect_stdout(sys.stderr):
            code = main(args)
        if code != 0:
            raise RuntimeError(f"warm-up of {args} ended with exit code {code}")
    if threading.active_count() != 1:   # forking with a live thread could copy a held lock into every child
        raise RuntimeError(f"threads still running after the warm-up: {threading.enumerate()}")


def serve() -> None:
    sys.path.insert(0, str(ROOT))
    for line in sys.stdin:
        request = json.loads(line)
        if "warm" in request:
            _warm(request["warm"], request["cwd"])
            reply = {"warmed": True}
        elif "run" in request:
            sys.stdout.flush()
            pid = os.fork()
            if pid == 0:
                _child(request["run"], request["cwd"], request["log"])
            reply = {"pid": pid}
        else:
            pid, status = os.waitpid(request["poll"], os.WNOHANG)
            reply = {"code": None if pid == 0 else os.waitstatus_to_exitcode(status)}
        print(json.dumps(reply), flush=True)


if __name__ == "__main__":
    serve()
