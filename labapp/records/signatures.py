"""Electronic signatures of a record: ``signatures.jsonl``, bound to the record's hash.

A signature is the signer's name, the UTC time, its meaning (:class:`Meaning`: reviewed or approved) and an
optional reason, made after the signer re-entered their password, and bound to the record's hash
(:func:`record_hash`: SHA-256 over the relative path and SHA-256 of every file of the record except
``audit.jsonl``, ``signatures.jsonl`` and hidden files) and to the head of its audit trail. Each line carries
its own SHA-256 (``hash``) and the audit trail's ``sign`` entry names it. Any later change of any file of
the record makes :func:`check_signatures` report the signature BROKEN; a wrong password is refused and the
refusal is audited.
"""
from __future__ import annotations

import enum
import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from labapp.errors import UsageError
from labapp.records import operators
from labapp.records.audit import (
    AUDIT_FILE,
    FINISH_ACTIONS,
    SIGNATURES_FILE,
    Action,
    AuditCheck,
    append,
    check_trail,
    entry_hash,
)
from labapp.records.fileio import sha256_file
from labapp.records.manifests import RUN_JSON
from labapp.records.verification import verify_run

__all__ = ["Meaning", "SignatureError", "SignatureState", "check_signatures", "check_signer", "read_signatures",
           "record_checks", "record_hash", "sign", "signed_heads", "trail_check"]

_UNHASHED = {AUDIT_FILE, SIGNATURES_FILE}


class Meaning(enum.StrEnum):
    """What a signature means (21 CFR 11.50: the meaning is part of every signature)."""

    REVIEWED = "reviewed"
    APPROVED = "approved"


class SignatureError(UsageError):
    """A signature refused: wrong password, a record that does not verify, or a folder that is not a record."""


def record_files(folder: str | Path) -> list[Path]:
    """The files a record's hash covers: every file under ``folder`` except the audit trail, the signatures
    and hidden files or folders (``.part`` leftovers), sorted by relative path."""
    folder = Path(folder)
    files = []
    for path in folder.rglob("*"):
        rel = path.relative_to(folder)
        if path.is_file() and not any(part.startswith(".") for part in rel.parts) and str(rel) not in _UNHASHED:
            files.append(path)
    return sorted(files, key=lambda p: p.relative_to(folder).as_posix())


def record_hash(folder: str | Path) -> str:
    """SHA-256 (hex) of the record: of the lines ``<relative path>\\t<SHA-256 of the file>\\n`` of
    :func:`record_files`, in order. A file added, removed, renamed or changed changes it."""
    folder = Path(folder)
    digest = hashlib.sha256()
    for path in record_files(folder):
        digest.update(f"{path.relative_to(folder).as_posix()}\t{sha256_file(path)}\n".encode())
    return digest.hexdigest()


def read_signatures(folder: str | Path) -> list[dict[str, Any]]:
    """The signatures of ``folder`` in file order (lines that do not parse are returned as ``{"line": n}``)."""
    path = Path(folder) / SIGNATURES_FILE
    if not path.is_file():
        return []
    out = []
    for number, line in enumerate(path.read_bytes().split(b"\n"), start=1):
        if line.strip():
            try:
                entry = json.loads(line)
                out.append(entry if isinstance(entry, dict) else {"line": number})
            except ValueError:
                out.append({"line": number})
    return out


def _is_record(folder: Path) -> bool:
    return (folder / RUN_JSON).is_file() or (folder / AUDIT_FILE).is_file()


def check_signer(signer: str) -> str:
    """``signer`` when they may sign: an operator of the users file, not the demo operator nor an unverified one.

    Raises
    ------
    SignatureError
        Saying why, and how to get an operator who can sign.
    """
    if signer == operators.DEMO_OPERATOR:
        raise SignatureError(f"the demo operator {signer!r} cannot sign; sign as an operator of the users file")
    if not operators.is_verified(signer):
        raise SignatureError(f"{signer!r} acts without a users file and cannot sign: a signature needs an operator "
                             f"with a password; create one with 'sfr users add NAME' (operators are then enforced "
                             f"for every recorded action)")
    return signer


def sign(folder: str | Path, meaning: Meaning | str, password: str, *, reason: str | None = None) -> dict[str, Any]:
    """Sign the record ``folder`` as the current operator, after checking their password.

    Returns the signature (as stored in ``signatures.jsonl``). The audit trail gets a ``sign`` entry; a wrong
    password gets a ``sign-refused`` entry and nothing else.

    Raises
    ------
    SignatureError
        For a wrong password, a folder that is not a record, a record that fails verification or whose
        audit trail is broken, an unknown meaning, or a signer who is the demo operator or unverified (no
        users file).
    labapp.records.operators.OperatorError
        When the process acts as nobody.
    """
    folder = Path(folder)
    try:
        meaning = Meaning(meaning)
    except ValueError:
        raise SignatureError(f"meaning {meaning!r}: expected one of {', '.join(m.value for m in Meaning)}") from None
    if not folder.is_dir() or not _is_record(folder):
        raise SignatureError(f"{folder} is not a record (no {RUN_JSON} or {AUDIT_FILE}); only records are signed")
    signer = check_signer(operators.require(f"signing {folder}"))
    if not operators.check_password(signer, password):
        append(folder, Action.SIGN_REFUSED, f"signature ({meaning}) refused: wrong password", operator=signer)
        raise SignatureError(f"signature refused: wrong password for operator {signer!r} (the refusal is in "
                             f"{folder / AUDIT_FILE})")
    problems = _record_problems(folder)
    if problems:
        raise SignatureError(f"{folder} cannot be signed: {problems[0]}")
    trail = check_trail(folder)
    head = trail.head
    signature: dict[str, Any] = {"signer": signer, "utc": operators.utc_now(), "meaning": str(meaning),
                                 "reason": " ".join(reason.split()) if reason else None,
                                 "record_hash": record_hash(folder), "audit_seq": head[0] if head else 0,
                                 "audit_hash": head[1] if head else None}
    signature["hash"] = entry_hash(signature)
    fd = os.open(folder / SIGNATURES_FILE, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, json.dumps(signature, sort_keys=True, ensure_ascii=False).encode() + b"\n")
        os.fsync(fd)
    finally:
        os.close(fd)
    append(folder, Action.SIGN, f"signed ({meaning}); record {signature['record_hash'][:16]}; signature "
           f"{signature['hash']}", operator=signer, reason=reason)
    return signature


def _record_problems(folder: Path) -> list[str]:
    """Why ``folder`` cannot be signed: its manifests or its audit trail fail their checks."""
    problems = []
    if (folder / RUN_JSON).is_file():
        report = verify_run(folder)
        if not report.ok:
            problems.append(f"it fails verification ({report.reason})")
    trail = check_trail(folder)
    problems += trail.problems
    return problems


@dataclass(frozen=True)
class SignatureState:
    """One signature and whether it still holds: ``intact`` False with ``why`` when the record changed after
    it, the signature line was edited, or the audit trail no longer holds its ``sign`` entry."""

    signature: dict[str, Any]
    intact: bool
    why: str

    def line(self) -> str:
        s = self.signature
        who = f"{s.get('meaning', '?')} by {s.get('signer', '?')} at {s.get('utc', '?')}"
        reason = f" (reason: {s['reason']})" if s.get("reason") else ""
        return f"SIGNATURE {who}{reason}: " + ("intact" if self.intact else f"BROKEN ({self.why})")


def check_signatures(folder: str | Path) -> list[SignatureState]:
    """Each signature of ``folder`` with whether it still holds (the record's hash now against the one signed)."""
    folder = Path(folder)
    signatures = read_signatures(folder)
    if not signatures:
        return []
    now = record_hash(folder)
    signed_in_trail = {str(e.get("detail", "")).rsplit("signature ", 1)[-1] for e in check_trail(folder).entries
                       if e.get("action") == Action.SIGN}
    states = []
    for sig in signatures:
        if "hash" not in sig or entry_hash(sig) != sig.get("hash"):
            states.append(SignatureState(sig, False, f"the signature line was edited or is unreadable "
                                                     f"({SIGNATURES_FILE})"))
        elif sig["hash"] not in signed_in_trail:
            states.append(SignatureState(sig, False, f"the audit trail has no 'sign' entry for it ({AUDIT_FILE})"))
        elif sig.get("record_hash") != now:
            states.append(SignatureState(sig, False, "the record changed after it was signed (record hash "
                                                     f"{str(sig.get('record_hash'))[:16]} signed, {now[:16]} now)"))
        else:
            states.append(SignatureState(sig, True, ""))
    return states


def signed_heads(folder: str | Path) -> dict[int, str]:
    """``audit seq -> hash`` recorded by the signatures (the trail must still hold them)."""
    return {int(s["audit_seq"]): str(s["audit_hash"]) for s in read_signatures(folder)
            if s.get("audit_hash") and isinstance(s.get("audit_seq"), int)}


def _names_operator(folder: Path) -> tuple[bool, Action | None]:
    """Whether ``folder``'s ``run.json`` names its operator, and the entry its status says came last."""
    if (folder / RUN_JSON).is_file():
        try:
            stored = json.loads((folder / RUN_JSON).read_text())
            if isinstance(stored, dict) and "operator" in stored:
                return True, FINISH_ACTIONS.get(stored.get("status"))
        except (OSError, ValueError):
            pass
    return False, None


def trail_check(folder: str | Path) -> AuditCheck:
    """The audit trail of ``folder`` checked as ``sfr verify`` and ``sfr audit`` both check it: its hash chain,
    the heads its signatures recorded, and a finished run's finishing entry (a trail cut off at its end)."""
    folder = Path(folder)
    return check_trail(folder, expect_last=_names_operator(folder)[1], pinned=signed_heads(folder))


def record_checks(folder: str | Path) -> tuple[list[str], list[str]]:
    """The audit-trail and signature findings on ``folder`` for ``sfr verify``: ``(problems, notes)``, one line
    each. A record that names its operator (``run.json``) or has signatures must have an intact trail; a
    finished run's trail must end with its finishing entry; every signature must still hold."""
    folder = Path(folder)
    named = _names_operator(folder)[0]
    trail = trail_check(folder)
    problems, notes = list(trail.problems), []
    if not trail.exists:
        if named or (folder / SIGNATURES_FILE).is_file():
            problems.append(f"the audit trail {AUDIT_FILE} is missing")
        elif (folder / RUN_JSON).is_file():
            notes.append(f"no audit trail ({AUDIT_FILE}): the record does not name its operators")
    else:
        operators_seen = sorted({str(e["operator"]) for e in trail.entries})
        notes.append(f"audit trail: {len(trail.entries)} entries by {', '.join(operators_seen) or 'nobody'}"
                     + ("" if trail.ok else " (BROKEN)"))
    for state in check_signatures(folder):
        (notes if state.intact else problems).append(state.line())
    return problems, notes
