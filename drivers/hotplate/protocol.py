"""Declarative command tables of stirring hotplates that speak NAMUR-style ASCII over RS-232.

Each device quantity is one declaration; the driver (`drivers.hotplate.heidolph`) and the emulator
(`drivers.sim.heidolph_emulator`) both read these tables, so neither formats strings by hand.

Heidolph MR Hei-Tec / Hei-Connect, German operating manual v1.3, chapter "RS 232 / USB": 9600 baud,
7 data bits, even parity, 1 stop bit; every command is answered by its echo (``IN_PV_3 25.3``);
lines end in ``\\r\\n`` after ``PA_NEW`` (``\\n\\r`` in the old protocol); at least 0.1 s between
commands; ``999.9`` stands for "no external probe"; "PC Err" after 10 s of silence while heating or
stirring (the connection check, ``CC_ON``/``CC_OFF``).

IKA RCT basic / RCT digital / C-MAG HS (IKA operating manuals, "Interface" chapter; same command
words in the RC 5 and RV 10 manuals): 9600 baud 7E1; commands end in "blank CR LF"; queries are
answered *without* echo, as the value followed by the channel number (``IN_PV_2`` -> ``25.3 2``);
set commands and ``START``/``STOP`` get no reply at all; plate ``IN_PV_2``, speed ``IN_PV_4``,
``OUT_SP_4`` speed, ``START_4``/``STOP_4`` stirring; no ``STATUS``; the watchdog is ``OUT_WD1@m``
(m = 20...1500 s, answered with the time).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from drivers.hotplate.base import HotplateError

NO_PROBE_C = 999.9
"""What the plate sends for the external probe temperature when no probe is plugged in."""


@dataclass(frozen=True)
class Reading:
    """A quantity the plate reports: the query command and its unit."""

    query: str
    unit: str


@dataclass(frozen=True)
class Setpoint:
    """A quantity the plate accepts: set command, read-back query, unit and the device's own range."""

    command: str
    readback: str
    unit: str
    low: float
    high: float
    decimals: int = 1

    def encode(self, value: float, limit: float | None = None) -> str:
        """Return the command line (no terminator) that sets ``value``.

        Parameters
        ----------
        value : float
            Requested value in ``unit``.
        limit : float, optional
            Client-side upper limit, tighter than the device range.

        Raises
        ------
        HotplateError
            If ``value`` is not finite or lies outside :meth:`allowed` ``(limit)``.
        """
        low, high = self.allowed(limit)
        if not math.isfinite(value) or not low <= value <= high:
            raise HotplateError(f"{self.command}: {value!r} {self.unit} is outside the allowed range "
                                f"[{low:g}, {high:g}] {self.unit}")
        return f"{self.command} {value:.{self.decimals}f}"

    def allowed(self, limit: float | None = None) -> tuple[float, float]:
        """The closed range ``(low, high)`` in ``unit`` that :meth:`encode` accepts under a client-side
        upper ``limit`` (None: the device's own range)."""
        return self.low, self.high if limit is None else min(self.high, limit)


@dataclass(frozen=True)
class ProtocolTable:
    """Everything that differs between two plates of the same NAMUR family.

    ``readings`` keys: ``probe_c``, ``plate_c``, ``speed_rpm``; ``setpoints`` keys: ``temperature``,
    ``speed``; ``actions`` keys: ``start_heating``, ``stop_heating``, ``start_stirring``,
    ``stop_stirring``, ``reset``, ``watchdog_on``, ``watchdog_off``, ``new_protocol``.
    ``echo`` says whether replies start with the command (if not, a query's reply ends in the query's
    channel number, which is checked); ``unanswered`` names the command words the plate does not
    reply to; ``keepalive`` is a command re-sent with every poll (a watchdog that only its own command
    re-arms); ``status_errors`` maps negative ``STATUS`` codes to messages. ``terminator`` ends the
    plate's replies (``old_terminator`` before ``new_protocol``), ``command_terminator`` the commands
    (default: ``terminator``).
    """

    name: str
    readings: Mapping[str, Reading]
    setpoints: Mapping[str, Setpoint]
    actions: Mapping[str, str]
    startup: tuple[str, ...]
    status: str | None = "STATUS"
    echo: bool = True
    terminator: str = "\r\n"
    old_terminator: str = "\n\r"
    command_terminator: str | None = None
    unanswered: frozenset[str] = frozenset()
    keepalive: str | None = None
    watchdog_s: float = 10.0
    status_errors: Mapping[int, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        missing = {"probe_c", "plate_c", "speed_rpm"} - set(self.readings)
        missing |= {"temperature", "speed"} - set(self.setpoints)
        missing |= {"start_heating", "stop_heating", "start_stirring", "stop_stirring"} - set(self.actions)
        if missing:
            raise ValueError(f"protocol table {self.name!r} lacks {sorted(missing)}")
        queries = {r.query for r in self.readings.values()} | {s.readback for s in self.setpoints.values()}
        if queries & self.unanswered:
            raise ValueError(f"protocol table {self.name!r}: queries cannot be unanswered: "
                             f"{sorted(queries & self.unanswered)}")

    @property
    def line_end(self) -> str:
        """What the client appends to every command."""
        return self.terminator if self.command_terminator is None else self.command_terminator

    def answers(self, command: str) -> bool:
        """Whether the plate replies to ``command`` (a full command line or its first word)."""
        return command.split(" ", 1)[0] not in self.unanswered

    def command_names(self) -> set[str]:
        """Every command word the plate understands (the part before the first space)."""
        names = {r.query for r in self.readings.values()} | set(self.actions.values())
        names |= {s.command for s in self.setpoints.values()} | {s.readback for s in self.setpoints.values()}
        if self.status:
            names.add(self.status)
        if self.keepalive:
            names.add(self.keepalive.split(" ", 1)[0])
        return names

    def payload(self, command: str, line: str) -> str:
        """The value part of the reply ``line`` to ``command`` ('' for a bare acknowledgement).

        Raises
        ------
        HotplateError
            If the reply does not echo the command (garbage, or the reply to another command).
        """
        word = command.split(" ", 1)[0]
        text = line.strip()
        if not self.echo:
            channel = _channel(word)
            if channel is None:
                return text
            value, _, tail = text.rpartition(" ")
            if tail != channel or not _is_number(value.strip()):
                raise HotplateError(f"reply {line!r} is not '<value> {channel}', the answer to {word!r}")
            return value.strip()
        head, _, rest = text.partition(" ")
        if head != word:
            raise HotplateError(f"reply {line!r} does not echo command {word!r}")
        return rest.strip()

    def reply(self, command: str, payload: str = "") -> str:
        """The reply line (no terminator) a plate sends to ``command``: used by the emulator."""
        word = command.split(" ", 1)[0]
        if not self.echo:
            channel = _channel(word)
            return f"{payload} {channel}" if channel is not None else payload
        return f"{word} {payload}" if payload else word

    def status_message(self, code: int) -> str | None:
        """The message of a negative ``STATUS`` code, or None for a healthy status."""
        if code >= 0:
            return None
        return self.status_errors.get(code, f"device error code {code}")


def _channel(word: str) -> str | None:
    """The channel number of a NAMUR query (``IN_PV_2`` -> ``'2'``), or None for other commands."""
    if not word.startswith("IN_"):
        return None
    tail = word.rsplit("_", 1)[-1]
    return tail if tail.isdigit() else None


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


HEIDOLPH_HEI_TEC = ProtocolTable(
    name="Heidolph MR Hei-Tec",
    readings={
        "probe_c": Reading("IN_PV_1", "C"),
        "plate_c": Reading("IN_PV_3", "C"),
        "speed_rpm": Reading("IN_PV_5", "rpm"),
    },
    setpoints={
        "temperature": Setpoint("OUT_SP_1", "IN_SP_1", "C", 0.0, 300.0),
        "speed": Setpoint("OUT_SP_3", "IN_SP_3", "rpm", 0.0, 1400.0, decimals=0),
    },
    actions={
        "start_heating": "START_1", "stop_heating": "STOP_1",
        "start_stirring": "START_2", "stop_stirring": "STOP_2",
        "reset": "RESET", "watchdog_on": "CC_ON", "watchdog_off": "CC_OFF",
        "new_protocol": "PA_NEW",
    },
    startup=("PA_NEW", "CC_ON"),
    status_errors={-1: "remote control blocked: the plate was stopped at its front panel "
                       "(switch it off and on, or send RESET)"},
)

IKA_RCT = ProtocolTable(
    name="IKA RCT / C-MAG",
    readings={
        "probe_c": Reading("IN_PV_1", "C"),
        "plate_c": Reading("IN_PV_2", "C"),
        "speed_rpm": Reading("IN_PV_4", "rpm"),
    },
    setpoints={
        # RCT digital: 0-310 C, 0-1500 rpm; whole degrees (the plate's setting resolution is 1 K)
        "temperature": Setpoint("OUT_SP_1", "IN_SP_1", "C", 0.0, 310.0, decimals=0),
        "speed": Setpoint("OUT_SP_4", "IN_SP_4", "rpm", 0.0, 1500.0, decimals=0),
    },
    actions={
        "start_heating": "START_1", "stop_heating": "STOP_1",
        "start_stirring": "START_4", "stop_stirring": "STOP_4",
        "reset": "RESET", "watchdog_on": "OUT_WD1@30",
    },
    startup=("OUT_WD1@30",),
    status=None,
    echo=False,
    terminator="\r\n",
    old_terminator="\r\n",
    command_terminator=" \r \n",
    unanswered=frozenset({"OUT_SP_1", "OUT_SP_4", "START_1", "STOP_1", "START_4", "STOP_4", "RESET"}),
    keepalive="OUT_WD1@30",
    watchdog_s=30.0,
)

TABLES: dict[str, ProtocolTable] = {"heidolph": HEIDOLPH_HEI_TEC, "ika": IKA_RCT}
"""Protocol tables by the short name used on the command line."""
