"""Operators: the local users file, salted password hashes, and the operator this process acts as.

Every recorded action (a run started, a drop, a stop, an analysis written into a record, a calibration, a
design, a signature) names the operator who did it. Operators are the users of a local JSON file
(:func:`users_path`: ``$SFR_USERS``, else ``$XDG_CONFIG_HOME/shape-from-release/users.json``, else
``~/.config/shape-from-release/users.json``), each with a per-user random salt and an scrypt hash of the
password (``hashlib.scrypt``, compared in constant time with ``hmac.compare_digest``). A user is never
deleted, only disabled, so that the names in old audit trails keep meaning one person.

The process acts as one operator at a time (:func:`log_in`, :func:`acting_as`, which also set
``SFR_OPERATOR`` for the processes it starts; that variable alone when nobody logged in). The simulated
demo acts as the built-in :data:`DEMO_OPERATOR`, which is not in any users file and records only on the
simulated bench.

Operators are enforced once the lab has a users file (:func:`enforced`): every recorded action then needs an
enabled operator of it. Until then (a research lab, a first try) an action is recorded under the name given
(``--operator``, ``SFR_OPERATOR``), else the login name, marked unverified (``"jdoe (unverified)"``,
:func:`unverified`): the records say who acted without any password, and an unverified operator cannot sign.
"""
from __future__ import annotations

import contextlib
import getpass
import hashlib
import hmac
import json
import os
import secrets
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

from labapp.errors import UsageError
from labapp.records.fileio import atomic_file

__all__ = ["DEMO_OPERATOR", "MIN_PASSWORD_CHARS", "OPERATOR_ENV", "UNVERIFIED", "USERS_ENV", "OperatorError", "User",
           "acting_as", "add_user", "check_password", "current", "enforced", "given", "is_verified", "load_users",
           "log_in", "log_out", "require", "set_enabled", "unverified", "users_path"]

USERS_ENV = "SFR_USERS"
"""Environment variable naming the users file (tests, a shared lab configuration)."""
OPERATOR_ENV = "SFR_OPERATOR"
"""Environment variable naming the operator when no ``--operator`` is given and nobody logged in."""
DEMO_OPERATOR = "demo (simulated bench)"
"""The built-in operator of ``sfr demo``: needs no users file, records only on the simulated bench."""
UNVERIFIED = " (unverified)"
"""Appended to the name of an operator acting without a users file (:func:`unverified`)."""
MIN_PASSWORD_CHARS = 8
USERS_FORMAT = 1
"""The layout of the users file this version writes (its ``format`` key)."""
_SCRYPT = {"n": 2 ** 14, "r": 8, "p": 1, "dklen": 32}
"""scrypt cost parameters of a new hash (stored with each hash, so that they can be raised later)."""
_MAX_NAME = 64


class OperatorError(UsageError):
    """No operator, an unknown or disabled one, or a bad users file; the message says what to do."""


@dataclass(frozen=True)
class User:
    """One operator of the users file: the name, whether enabled, when created (UTC ISO 8601), and the scrypt
    salt and hash (hex) with the cost parameters they were made with."""

    name: str
    enabled: bool
    created_utc: str
    salt: str
    hash: str
    n: int
    r: int
    p: int


def utc_now() -> str:
    """Now as UTC ISO 8601 with milliseconds: ``2026-12-03T10:15:02.123Z``."""
    now = time.time()
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(now)) + f".{int(now % 1 * 1000):03d}Z"


def users_path() -> Path:
    """Where the users file is: ``$SFR_USERS``, else the per-user configuration folder."""
    if os.environ.get(USERS_ENV):
        return Path(os.environ[USERS_ENV])
    base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config")
    return base / "shape-from-release" / "users.json"


def enforced() -> bool:
    """Whether operators are enforced: the lab has a users file (:func:`users_path`). Then every recorded action
    needs an enabled operator of it; without one, names are recorded unverified (:func:`unverified`)."""
    return users_path().exists()


def unverified(name: str) -> str:
    """``name`` as recorded without a users file: ``"name (unverified)"`` (a name already marked is kept)."""
    return name if name.endswith(UNVERIFIED) else f"{name}{UNVERIFIED}"


def is_verified(name: str) -> bool:
    """Whether ``name`` is an operator checked against a users file (not marked unverified)."""
    return not name.endswith(UNVERIFIED)


def _login_name() -> str:
    try:
        return getpass.getuser()
    except (OSError, KeyError):     # no login name in the environment or the password database
        return "unknown user"


def _hash(password: str, salt: bytes, n: int, r: int, p: int) -> str:
    return hashlib.scrypt(password.encode(), salt=salt, n=n, r=r, p=p, dklen=_SCRYPT["dklen"],
                          maxmem=256 * n * r + (1 << 20)).hex()


def load_users(path: Path | None = None) -> dict[str, User]:
    """The users of the users file by name (empty when the file does not exist).

    Raises
    ------
    OperatorError
        If the file cannot be read or is not a users file of a layout this version knows.
    """
    path = users_path() if path is None else Path(path)
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
        if not isinstance(data, dict) or data.get("format") != USERS_FORMAT:
            raise ValueError(f"not a users file of format {USERS_FORMAT}")
        return {u["name"]: User(**u) for u in data["users"]}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise OperatorError(f"{path}: the users file cannot be read ({exc})") from None


def _save(users: dict[str, User], path: Path) -> None:
    """Write the users file atomically, readable by its owner only."""
    path.parent.mkdir(parents=True, exist_ok=True)
    data = json.dumps({"format": USERS_FORMAT, "users": [asdict(u) for u in users.values()]}, indent=2) + "\n"
    with atomic_file(path, mode=0o600) as fh:
        fh.write(data.encode())


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name.strip() or name != name.strip() or len(name) > _MAX_NAME \
            or not name.isprintable():
        raise OperatorError(f"operator name {name!r}: expected 1 to {_MAX_NAME} printable characters without "
                            "leading or trailing spaces")
    if name == DEMO_OPERATOR:
        raise OperatorError(f"operator name {name!r} is the built-in demo operator's")
    if not is_verified(name):
        raise OperatorError(f"operator name {name!r}: a name ending {UNVERIFIED!r} marks an operator without a "
                            "users file")
    return name


def add_user(name: str, password: str, path: Path | None = None) -> User:
    """Add an operator with a new random salt and the scrypt hash of ``password``.

    Raises
    ------
    OperatorError
        For a bad or existing name, or a password shorter than :data:`MIN_PASSWORD_CHARS`.
    """
    path = users_path() if path is None else Path(path)
    _check_name(name)
    if len(password) < MIN_PASSWORD_CHARS:
        raise OperatorError(f"the password of {name!r} must have at least {MIN_PASSWORD_CHARS} characters")
    users = load_users(path)
    if name in users:
        raise OperatorError(f"operator {name!r} exists in {path} (users are disabled, never replaced)")
    salt = secrets.token_bytes(16)
    user = User(name, True, utc_now(), salt.hex(), _hash(password, salt, _SCRYPT["n"], _SCRYPT["r"], _SCRYPT["p"]),
                _SCRYPT["n"], _SCRYPT["r"], _SCRYPT["p"])
    users[name] = user
    _save(users, path)
    return user


def set_enabled(name: str, enabled: bool, path: Path | None = None) -> User:
    """Enable or disable an operator (a disabled operator can neither act nor sign)."""
    path = users_path() if path is None else Path(path)
    users = load_users(path)
    if name not in users:
        raise OperatorError(f"no operator {name!r} in {path}")
    users[name] = User(**dict(asdict(users[name]), enabled=enabled))
    _save(users, path)
    return users[name]


def check_password(name: str, password: str, path: Path | None = None) -> bool:
    """Whether ``password`` is the enabled operator ``name``'s (constant-time comparison of the hashes)."""
    user = load_users(path).get(name)
    if user is None or not user.enabled:
        return False
    return hmac.compare_digest(_hash(password, bytes.fromhex(user.salt), user.n, user.r, user.p), user.hash)


def _known(name: str) -> str:
    """``name`` when it is an enabled operator of the users file (or the demo operator); without a users file,
    ``name`` marked unverified."""
    if name == DEMO_OPERATOR:
        return name
    if not enforced():
        return unverified(name)
    users = load_users()
    if name not in users:
        raise OperatorError(f"operator {name!r} is not in the users file {users_path()} (operators are enforced "
                            "once it exists; create it with 'sfr users add NAME')")
    if not users[name].enabled:
        raise OperatorError(f"operator {name!r} is disabled in {users_path()}")
    return name


_session: str | None = None


def log_in(name: str) -> str:
    """Act as ``name`` from now on in this process and the processes it starts (Dask workers, `sfr`
    subprocesses: ``SFR_OPERATOR`` is set); checked against the users file."""
    global _session
    _session = _known(name)
    os.environ[OPERATOR_ENV] = _session
    return _session


def log_out() -> None:
    """Act as nobody: the session and ``SFR_OPERATOR`` are cleared."""
    global _session
    _session = None
    os.environ.pop(OPERATOR_ENV, None)


@contextlib.contextmanager
def acting_as(name: str) -> Iterator[str]:
    """Act as ``name`` inside the ``with`` block, then as before (``SFR_OPERATOR`` too)."""
    global _session
    before, before_env = _session, os.environ.get(OPERATOR_ENV)
    log_in(name)
    try:
        yield name
    finally:
        _session = before
        if before_env is None:
            os.environ.pop(OPERATOR_ENV, None)
        else:
            os.environ[OPERATOR_ENV] = before_env


def given() -> str | None:
    """The operator named for this process: the one logged in, else ``$SFR_OPERATOR`` (checked as by
    :func:`log_in`), else None.

    Raises
    ------
    OperatorError
        If the name in ``SFR_OPERATOR`` is not an enabled operator of the users file.
    """
    if _session is not None:
        return _session
    env = os.environ.get(OPERATOR_ENV, "").strip()
    return _known(env) if env else None


def current() -> str | None:
    """The operator this process acts as: the one named (:func:`given`), else (without a users file) the login
    name marked unverified, else None.

    Raises
    ------
    OperatorError
        If the name in ``SFR_OPERATOR`` is not an enabled operator of the users file.
    """
    name = given()
    if name is not None or enforced():
        return name
    return unverified(_login_name())


def require(action: str) -> str:
    """The operator doing ``action``; refused when there is none (with a users file: no operator, no recorded
    action; without one the login name is recorded, unverified).

    Raises
    ------
    OperatorError
        Naming the action and how to give an operator.
    """
    name = current()
    if name is None:
        raise OperatorError(f"no operator: {action} is recorded under an operator's name of the users file "
                            f"{users_path()}; give --operator NAME or set {OPERATOR_ENV}")
    return name
