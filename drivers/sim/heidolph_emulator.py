"""A Heidolph MR Hei-Tec (or an IKA RCT) that speaks its RS-232 bytes over a Linux pseudo-terminal.

The emulator answers the commands of `drivers.hotplate.protocol.HEIDOLPH_HEI_TEC` (or of any other
table, e.g. ``IKA_RCT``: no echo, unanswered set commands) from a thread,
advances the thermal model of `drivers.sim.hotplate_model` in (optionally accelerated) simulated
time, runs the plate's own connection check ("PC Err": heating and stirring off after
``watchdog_s`` of silence) and injects faults on request. Clients open `HeidolphEmulator.path`, a
symlink that stays valid across a dropped link.

A pseudo-terminal keeps the termios settings of the last client (7E1), and pyserial's next open then
fails with EINVAL; the emulator therefore restores the original settings whenever a client leaves
(seen as POLLHUP on the master side).
"""
from __future__ import annotations

import logging
import os
import re
import select
import shutil
import tempfile
import termios
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from drivers.hotplate.protocol import HEIDOLPH_HEI_TEC, NO_PROBE_C, ProtocolTable
from drivers.sim.hotplate_model import PlateState, ThermalParams, step

log = logging.getLogger(__name__)

_LINE_END = re.compile(rb"[\r\n]+")


@dataclass(frozen=True)
class EmulatorState:
    """A snapshot of the emulated plate.

    ``water_c`` is what the external probe reads (the app shows it as the probe temperature);
    ``sim_time_s`` is simulated seconds since `HeidolphEmulator.start`.
    """

    plate: PlateState
    sim_time_s: float
    remote: bool
    watchdog_on: bool
    pc_err: bool
    new_protocol: bool
    client_connected: bool
    commands: int

    @property
    def setpoint_c(self) -> float:
        return self.plate.setpoint_c

    @property
    def setpoint_rpm(self) -> float:
        return self.plate.setpoint_rpm

    @property
    def heating(self) -> bool:
        return self.plate.heating

    @property
    def stirring(self) -> bool:
        return self.plate.stirring

    @property
    def plate_c(self) -> float:
        return self.plate.plate_c

    @property
    def water_c(self) -> float:
        return self.plate.water_c

    @property
    def speed_rpm(self) -> float:
        return self.plate.speed_rpm


class HeidolphEmulator:
    """Emulated hotplate on a pseudo-terminal; ``start()`` returns the device path.

    Parameters
    ----------
    speed : float
        Time acceleration of the thermal model and stirring ramp (simulated s per real s), > 0.
    params : ThermalParams
        Thermal model constants.
    watchdog_s : float, optional
        Real seconds of silence after which the plate shows "PC Err" and stops heating and stirring
        (while the connection check is on); default the table's 10 s.
    reply_delay_s : float
        Real seconds between a command and its reply.
    noise_c : float
        Standard deviation of temperature read-out noise, degrees C.
    probe_connected : bool
        False makes the plate report 999.9 for the probe and regulate the plate itself.
    seed : int, optional
        Seed of the read-out noise and garbage generator.
    table : ProtocolTable
        The command table to speak.
    clock : callable
        Real-time clock in seconds (monotonic); injectable for tests.
    """

    def __init__(self, *, speed: float = 1.0, params: ThermalParams = ThermalParams(),
                 watchdog_s: float | None = None, reply_delay_s: float = 0.01, noise_c: float = 0.05,
                 probe_connected: bool = True, seed: int | None = None,
                 table: ProtocolTable = HEIDOLPH_HEI_TEC, clock: Callable[[], float] = time.monotonic) -> None:
        if speed <= 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        if reply_delay_s < 0 or noise_c < 0:
            raise ValueError(f"reply_delay_s and noise_c must be >= 0, got {reply_delay_s!r}, {noise_c!r}")
        self._table = table
        self._params = params
        self._speed = float(speed)
        self._watchdog_s = table.watchdog_s if watchdog_s is None else float(watchdog_s)
        self._reply_delay_s = reply_delay_s
        self._noise_c = noise_c
        self._rng = np.random.default_rng(seed)
        self._clock = clock
        self._lock = threading.Lock()
        self._plate = PlateState(plate_c=params.ambient_c, water_c=params.ambient_c, probe_connected=probe_connected)
        self._sim_t = 0.0
        self._remote = self._watchdog_on = self._pc_err = self._new_protocol = False
        self._client = False
        self._commands = 0
        self._silent = False
        self._garbage = 0
        self._slow_s = 0.0
        self._relink_at: float | None = None
        self._master: int | None = None
        self._saved_attrs: list | None = None
        self._dir: str | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._last_real = self._last_rx = clock()

    # -- life cycle ---------------------------------------------------------------------------------

    def start(self) -> str:
        """Open the pseudo-terminal, start serving, and return the device path clients open."""
        if self._thread is not None:
            raise RuntimeError("emulator already started")
        self._dir = tempfile.mkdtemp(prefix="heidolph-emu-")
        self._open_pty()
        self._last_real = self._last_rx = self._clock()
        self._thread = threading.Thread(target=self._serve, name="heidolph-emulator", daemon=True)
        self._thread.start()
        log.info("%s emulator on %s (x%g time)", self._table.name, self.path, self._speed)
        return self.path

    def stop(self) -> None:
        """Stop serving, close the pseudo-terminal and remove the device path."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._close_pty()
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    def __enter__(self) -> "HeidolphEmulator":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def path(self) -> str:
        """The device path (a symlink to the current pseudo-terminal)."""
        if self._dir is None:
            raise RuntimeError("emulator not started")
        return os.path.join(self._dir, "tty")

    @property
    def state(self) -> EmulatorState:
        """A consistent snapshot of the plate, advanced to now."""
        with self._lock:
            self._advance()
            return EmulatorState(self._plate, self._sim_t, self._remote, self._watchdog_on, self._pc_err,
                                 self._new_protocol, self._client, self._commands)

    # -- controls and faults --------------------------------------------------------------------------

    def set_speed(self, speed: float) -> None:
        """Change the time acceleration (simulated s per real s), > 0."""
        if speed <= 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        with self._lock:
            self._advance()
            self._speed = float(speed)

    def set_probe(self, connected: bool) -> None:
        """Plug the external probe in or out (out: the plate reports 999.9)."""
        with self._lock:
            self._plate = replace(self._plate, probe_connected=connected)

    def set_silent(self, silent: bool) -> None:
        """Fault: ignore every command (no reply, no effect) until called with False."""
        self._silent = silent

    def inject_garbage(self, n_replies: int = 1) -> None:
        """Fault: answer the next ``n_replies`` commands with random bytes instead of the reply."""
        self._garbage += n_replies

    def set_reply_delay(self, extra_s: float) -> None:
        """Fault: delay every reply by ``extra_s`` more real seconds (0 restores)."""
        self._slow_s = max(0.0, extra_s)

    def drop_link(self, down_s: float) -> None:
        """Fault: hang up the line (clients see I/O errors) and come back after ``down_s`` real s."""
        with self._lock:
            self._relink_at = self._clock() + down_s
        log.info("emulator: link dropped for %.2f s", down_s)

    def restore_link(self) -> None:
        """End a :meth:`drop_link` now: the line comes back at the next turn of the serving loop."""
        with self._lock:
            if self._relink_at is not None:
                self._relink_at = self._clock()
        log.info("emulator: link restored on request")

    def disturb_water(self, delta_c: float) -> None:
        """Fault: the water's temperature jumps by ``delta_c`` C (cold water poured in: negative)."""
        with self._lock:
            self._advance()
            self._plate = replace(self._plate, water_c=self._plate.water_c + delta_c)

    def trip_watchdog(self) -> None:
        """Fault: show "PC Err" now, as if the connection check had expired."""
        with self._lock:
            self._trip()

    # -- internals ----------------------------------------------------------------------------------

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        pts = os.ttyname(slave)
        os.close(slave)  # without a client the master sees POLLHUP: that is how a leaving client shows
        self._saved_attrs = termios.tcgetattr(master)
        self._master = master
        tmp = self.path + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(pts, tmp)
        os.replace(tmp, self.path)
        log.debug("emulator pty %s -> %s", self.path, pts)

    def _close_pty(self) -> None:
        if self._master is not None:
            os.close(self._master)
            self._master = None
        if self._dir is not None and os.path.lexists(self.path):
            os.unlink(self.path)
        self._client = False

    def _advance(self) -> None:
        now = self._clock()
        dt = (now - self._last_real) * self._speed
        self._last_real = now
        if dt > 0:
            self._plate = step(self._plate, dt, self._params)
            self._sim_t += dt
        quiet = now - self._last_rx
        if self._watchdog_on and (self._plate.heating or self._plate.stirring) and quiet > self._watchdog_s:
            self._trip()

    def _trip(self) -> None:
        if not self._pc_err:
            log.info("emulator: PC Err (no command for %.1f s): heating and stirring off", self._watchdog_s)
        self._pc_err = True
        self._plate = replace(self._plate, heating=False, stirring=False)

    def _serve(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            with self._lock:
                self._advance()
                relink_at = self._relink_at
            if relink_at is not None:
                if self._master is not None:
                    self._close_pty()
                    buffer = b""
                if self._clock() < relink_at:
                    time.sleep(0.01)
                    continue
                with self._lock:
                    self._relink_at = None
                self._open_pty()
                log.info("emulator: link back on %s", self.path)
            poller = select.poll()
            poller.register(self._master, select.POLLIN)
            events = poller.poll(20)
            hangup = any(ev & select.POLLHUP for _, ev in events)
            if any(ev & select.POLLIN for _, ev in events):
                # a client that writes and closes at once (unanswered commands) leaves POLLIN and POLLHUP
                buffer = self._receive(buffer)
            if hangup:
                if self._client:
                    self._client_left()
                    buffer = b""
                time.sleep(0.01)
                continue
            if events:
                self._client = True

    def _receive(self, buffer: bytes) -> bytes:
        """Read what the client sent, handle every complete line, return the incomplete rest."""
        try:
            data = os.read(self._master, 4096)
        except OSError:
            return buffer
        buffer += bytes(b & 0x7F for b in data)
        *lines, buffer = _LINE_END.split(buffer)
        for line in lines:
            if line.strip():
                self._handle(line.decode("ascii", "replace").strip())
        return buffer

    def _client_left(self) -> None:
        termios.tcflush(self._master, termios.TCIOFLUSH)
        termios.tcsetattr(self._master, termios.TCSANOW, self._saved_attrs)
        self._client = False  # only now: a client that sees the port free may reopen it at once
        log.debug("emulator: client left, terminal settings restored")

    def _handle(self, line: str) -> None:
        if self._silent:
            return
        with self._lock:
            self._advance()
            self._last_rx = self._clock()
            self._pc_err = False
            self._commands += 1
            payload = self._execute(line)
            terminator = self._table.terminator if self._new_protocol else self._table.old_terminator
        if payload is None:
            log.debug("emulator: unknown command %r ignored", line)
            return
        if not self._table.answers(line):
            return
        delay = self._reply_delay_s + self._slow_s
        if delay:
            time.sleep(delay)
        if self._garbage > 0:
            self._garbage -= 1
            text = bytes(self._rng.integers(33, 127, size=12).astype(np.uint8)).decode("ascii")
        else:
            text = self._table.reply(line, payload)
        try:
            os.write(self._master, (text + terminator).encode("ascii"))
        except OSError as exc:
            log.debug("emulator: reply lost (%s)", exc)

    def _execute(self, line: str) -> str | None:
        """Apply one command; return the reply payload ('' for a bare echo) or None if unknown."""
        t = self._table
        word, _, arg = line.partition(" ")
        p = self._plate
        for key, reading in t.readings.items():
            if word == reading.query:
                return self._read(key)
        for key, sp in t.setpoints.items():
            if word == sp.readback:
                value = p.setpoint_c if key == "temperature" else p.setpoint_rpm
                return f"{value:.{sp.decimals}f}"
            if word == sp.command:
                try:
                    value = min(max(float(arg), sp.low), sp.high)
                except ValueError:
                    return None
                field = "setpoint_c" if key == "temperature" else "setpoint_rpm"
                self._plate = replace(p, **{field: value})
                return f"{value:.{sp.decimals}f}"
        if word == t.status:
            return str((1 if p.heating or p.stirring else 2) if self._remote else 0)
        actions = {v: k for k, v in t.actions.items()}
        action = actions.get(word)
        if action is None:
            return None
        if action in ("start_heating", "stop_heating", "start_stirring", "stop_stirring"):
            self._remote = True
            on = action.startswith("start")
            field = "heating" if action.endswith("heating") else "stirring"
            self._plate = replace(p, **{field: on})
        elif action == "reset":
            self._remote = self._watchdog_on = False
            self._plate = replace(p, heating=False, stirring=False)
        elif action in ("watchdog_on", "watchdog_off"):
            self._watchdog_on = action == "watchdog_on"
            return word.partition("@")[2]  # IKA's OUT_WD1@m is answered with the time m
        elif action == "new_protocol":
            self._new_protocol = True
        return ""

    def _read(self, key: str) -> str:
        p = self._plate
        noise = float(self._rng.normal(0.0, self._noise_c)) if self._noise_c else 0.0
        if key == "probe_c":
            return f"{p.water_c + noise:.1f}" if p.probe_connected else f"{NO_PROBE_C:.1f}"
        if key == "plate_c":
            return f"{p.plate_c + noise:.1f}"
        return f"{p.speed_rpm:.0f}"
