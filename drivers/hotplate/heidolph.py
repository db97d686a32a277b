"""`HeidolphHotplate` (alias `NamurHotplate`): a Heidolph MR Hei-Tec, or any plate of
`drivers.hotplate.protocol` (``table=IKA_RCT`` for IKA RCT / C-MAG), over pyserial.

The port is opened with `serial.serial_for_url`, so ``/dev/ttyUSB0``, ``socket://host:port`` and the
emulator's pseudo-terminal all work. Every exchange goes through `_exchange` (framing, pacing of at
least 0.1 s, reply check); a keep-alive thread polls the plate so its connection check never fires
while the app is alive; a lost link is reopened with exponential back-off and the commanded state is
restored. Heating and stirring are switched off by `close`, by an ``atexit`` hook, and (if the process
dies hard) by the plate's own connection check.
"""
from __future__ import annotations

import atexit
import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable

import serial

from drivers.hotplate.base import HotplateError, HotplateReading
from drivers.hotplate.protocol import HEIDOLPH_HEI_TEC, NO_PROBE_C, ProtocolTable

log = logging.getLogger(__name__)

try:
    import termios
    _LINK_ERRORS: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
except ImportError:  # not POSIX: pyserial reports everything as SerialException or OSError
    _LINK_ERRORS = (serial.SerialException, OSError)


@dataclass(frozen=True)
class HotplateConfig:
    """Client-side limits and link timing. Temperatures in degrees C, speeds in rpm, times in s."""

    max_temp_c: float = 100.0
    max_speed_rpm: float = 600.0
    timeout_s: float = 1.0
    pace_s: float = 0.1
    poll_interval_s: float = 2.0
    retries: int = 2
    reconnect_attempts: int = 5
    backoff_s: float = 0.5
    backoff_max_s: float = 8.0
    restore_on_reconnect: bool = True

    def __post_init__(self) -> None:
        for name, key in (("max_temp_c", "temperature"), ("max_speed_rpm", "speed")):
            value, device = getattr(self, name), HEIDOLPH_HEI_TEC.setpoints[key]
            if not 0 < value <= device.high:
                raise ValueError(f"{name} must be in (0, {device.high:g}] {device.unit}, got {value!r}")
        if self.pace_s < 0.1:
            raise ValueError(f"pace_s must be >= 0.1 s (the plate's minimum pause), got {self.pace_s!r}")
        if self.timeout_s <= 0 or self.backoff_s <= 0 or self.backoff_max_s < self.backoff_s:
            raise ValueError(f"timeout_s and backoff_s must be > 0 and backoff_max_s >= backoff_s, got "
                             f"{self.timeout_s!r}, {self.backoff_s!r}, {self.backoff_max_s!r}")
        if not 0 < self.poll_interval_s < HEIDOLPH_HEI_TEC.watchdog_s:
            raise ValueError(f"poll_interval_s must be in (0, {HEIDOLPH_HEI_TEC.watchdog_s}) s so the plate's "
                             f"connection check never fires, got {self.poll_interval_s!r}")
        if self.retries < 0 or self.reconnect_attempts < 1:
            raise ValueError(f"retries must be >= 0 and reconnect_attempts >= 1, got "
                             f"{self.retries!r}, {self.reconnect_attempts!r}")

    def setpoint_range(self, key: str, table: ProtocolTable = HEIDOLPH_HEI_TEC) -> tuple[float, float]:
        """The closed range a driver with this config accepts for a setpoint of ``table``: ``"temperature"``
        (C, capped by ``max_temp_c``) or ``"speed"`` (rpm, capped by ``max_speed_rpm``)."""
        limit = {"temperature": self.max_temp_c, "speed": self.max_speed_rpm}[key]
        return table.setpoints[key].allowed(limit)


class HeidolphHotplate:
    """A stirring hotplate on a serial URL; satisfies `drivers.hotplate.base.Hotplate`.

    Parameters
    ----------
    url : str
        Anything `serial.serial_for_url` opens (``/dev/ttyUSB0``, ``socket://host:4001``, a pty path).
    config : HotplateConfig
        Client-side limits and timing.
    table : ProtocolTable
        Command table of the plate.
    on_reading : callable, optional
        Called from the keep-alive thread with every `HotplateReading`.
    keep_alive : bool
        Poll the plate every ``config.poll_interval_s`` from a background thread.
    """

    def __init__(self, url: str, *, config: HotplateConfig = HotplateConfig(),
                 table: ProtocolTable = HEIDOLPH_HEI_TEC,
                 on_reading: Callable[[HotplateReading], None] | None = None, keep_alive: bool = True) -> None:
        self.url = url
        self.config = config
        self.table = table
        self._on_reading = on_reading
        self._keep_alive = keep_alive
        self._port: serial.SerialBase | None = None
        self._lock = threading.RLock()
        self._last_io = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._setpoint_c: float | None = None
        self._setpoint_rpm: float | None = None
        self._heating = False
        self._stirring = False
        self.reconnects = 0
        self.watchdog_trips = 0
        self.last_reading: HotplateReading | None = None

    # -- Hotplate protocol ----------------------------------------------------------------------------

    def connect(self) -> None:
        """Open the port, switch to the new protocol and the connection check, start the keep-alive."""
        with self._lock:
            self._open()
        atexit.register(self._atexit)
        if self._keep_alive and self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._poll_loop, name=f"hotplate-{self.url}", daemon=True)
            self._thread.start()
        log.info("%s connected on %s", self.table.name, self.url)

    def set_temperature(self, temp_c: float) -> None:
        """Set the temperature setpoint, degrees C (probe temperature when a probe is plugged in)."""
        self._set("temperature", temp_c)
        self._setpoint_c = temp_c

    def set_speed(self, speed_rpm: float) -> None:
        """Set the stirring speed setpoint, rpm."""
        self._set("speed", speed_rpm)
        self._setpoint_rpm = speed_rpm

    def _limit(self, key: str) -> float:
        return self.config.setpoint_range(key, self.table)[1]

    def _set(self, key: str, value: float) -> None:
        """Send a setpoint; if the plate does not answer set commands, read it back to confirm it."""
        sp = self.table.setpoints[key]
        line = sp.encode(value, self._limit(key))
        self._exchange(line)
        if not self.table.answers(line):
            got = float(self._exchange(sp.readback))
            if abs(got - value) > 0.5 * 10 ** -sp.decimals + 1e-9:
                raise HotplateError(f"{self.url}: {line!r} was not taken: {sp.readback} reads back "
                                    f"{got:g} {sp.unit}")

    def start_heating(self) -> None:
        self._exchange(self.table.actions["start_heating"])
        self._heating = True

    def stop_heating(self) -> None:
        self._heating = False
        self._exchange(self.table.actions["stop_heating"])

    def start_stirring(self) -> None:
        self._exchange(self.table.actions["start_stirring"])
        self._stirring = True

    def stop_stirring(self) -> None:
        self._stirring = False
        self._exchange(self.table.actions["stop_stirring"])

    def read(self) -> HotplateReading:
        """Poll every quantity once.

        Raises
        ------
        HotplateError
            On a lost link that could not be restored, garbage that persists, or a negative STATUS.
        """
        t = self.table
        if t.keepalive:
            self._exchange(t.keepalive)
        probe = float(self._exchange(t.readings["probe_c"].query))
        plate = float(self._exchange(t.readings["plate_c"].query))
        speed = float(self._exchange(t.readings["speed_rpm"].query))
        sp_c = float(self._exchange(t.setpoints["temperature"].readback))
        sp_rpm = float(self._exchange(t.setpoints["speed"].readback))
        running = True
        if t.status:
            code = int(self._exchange(t.status))
            message = t.status_message(code)
            if message:
                raise HotplateError(f"{self.url}: {message}")
            running = code != 2
        if not running and (self._heating or self._stirring):
            running = self._watchdog_tripped()
        reading = HotplateReading(
            plate_c=plate, probe_c=None if probe >= NO_PROBE_C - 0.05 else probe, speed_rpm=speed,
            setpoint_c=sp_c, setpoint_rpm=sp_rpm, heating=self._heating and running,
            stirring=self._stirring and running, t_unix_s=time.time())
        self.last_reading = reading
        return reading

    def close(self) -> None:
        """Switch heating and stirring off (best effort), stop the keep-alive and release the port."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.config.timeout_s * 10)
            self._thread = None
        try:
            if self._port is not None:
                self._safe_off()
        finally:
            atexit.unregister(self._atexit)
            with self._lock:
                if self._port is not None:
                    self._port.close()
                    self._port = None
        log.info("%s on %s closed", self.table.name, self.url)

    def __enter__(self) -> "HeidolphHotplate":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- link -----------------------------------------------------------------------------------------

    def identify(self) -> HotplateReading:
        """Query the plate's readings and setpoints with read-only commands and close the port again.

        Nothing that could change the plate's state is sent (no protocol switch, no connection check,
        no setpoint, no switching off): the safe first contact with a port that may hold another device,
        or a plate another program controls. ``heating``/``stirring`` are reported False (unknown).

        Raises
        ------
        HotplateError
            If the port cannot be opened or does not answer the queries as this table's plate does.
        """
        t = self.table
        with self._lock:
            self._open(startup=False)
            try:
                values = {key: self._query_number(r.query) for key, r in t.readings.items()}
                values.update({key: self._query_number(sp.readback) for key, sp in t.setpoints.items()})
            finally:
                self._port.close()
                self._port = None
        probe = values["probe_c"]
        return HotplateReading(plate_c=values["plate_c"], probe_c=None if probe >= NO_PROBE_C - 0.05 else probe,
                               speed_rpm=values["speed_rpm"], setpoint_c=values["temperature"],
                               setpoint_rpm=values["speed"], heating=False, stirring=False, t_unix_s=time.time())

    def _query_number(self, query: str) -> float:
        try:
            return float(self._exchange_once(query))
        except (HotplateError, ValueError) as exc:
            raise HotplateError(f"{self.url} did not answer {query!r} as a {self.table.name} does: {exc}") from exc

    def _open(self, startup: bool = True) -> None:
        try:
            self._port = serial.serial_for_url(self.url, baudrate=9600, bytesize=serial.SEVENBITS,
                                               parity=serial.PARITY_EVEN, stopbits=serial.STOPBITS_ONE,
                                               timeout=self.config.timeout_s, write_timeout=self.config.timeout_s)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise HotplateError(f"cannot open hotplate port {self.url}: {exc}") from exc
        for line in self.table.startup if startup else ():
            self._exchange_once(line)

    def _write(self, line: str) -> None:
        """Framing, outbound: pace, drop stale input, send ``line`` plus terminator."""
        wait = self.config.pace_s - (time.monotonic() - self._last_io)
        if wait > 0:
            time.sleep(wait)
        self._port.reset_input_buffer()
        self._port.write((line + self.table.line_end).encode("ascii"))
        self._last_io = time.monotonic()

    def _read(self, line: str) -> str:
        """Framing, inbound: one reply line (either terminator order), or HotplateError on timeout."""
        raw = self._port.read_until(b"\n")
        self._last_io = time.monotonic()
        if not raw.endswith(b"\n"):
            raise HotplateError(f"{self.url}: no reply to {line!r} within {self.config.timeout_s} s"
                                + (f" (got {raw!r})" if raw else ""))
        try:
            return raw.decode("ascii").strip("\r\n ")
        except UnicodeDecodeError as exc:
            raise HotplateError(f"{self.url}: reply to {line!r} is not ASCII: {raw!r}") from exc

    def _exchange_once(self, line: str) -> str:
        if self._port is None:
            raise HotplateError(f"hotplate on {self.url} is not connected")
        self._write(line)
        if not self.table.answers(line):
            self._port.flush()  # no reply to wait for: at least see the bytes leave before going on
            return ""
        return self.table.payload(line, self._read(line))

    def _exchange(self, line: str) -> str:
        """Send ``line`` and return the reply payload; retry garbage and timeouts, reopen a lost link."""
        last: Exception | None = None
        with self._lock:
            for attempt in range(self.config.retries + 1):
                try:
                    return self._exchange_once(line)
                except HotplateError as exc:
                    last = exc
                    log.warning("%s (attempt %d of %d)", exc, attempt + 1, self.config.retries + 1)
                except _LINK_ERRORS as exc:
                    last = exc
                    log.warning("%s: link lost during %r: %s", self.url, line, exc)
                    self._reconnect()
        raise HotplateError(f"{self.url}: no valid reply to {line!r} after {self.config.retries + 1} "
                            f"attempts: {last}") from last

    def _reconnect(self) -> None:
        """Reopen the port with exponential back-off and restore the commanded state."""
        if self._port is not None:
            try:
                self._port.close()
            except _LINK_ERRORS:
                pass
            self._port = None
        delay = self.config.backoff_s
        for attempt in range(1, self.config.reconnect_attempts + 1):
            time.sleep(delay)
            try:
                self._open()
                if self.config.restore_on_reconnect:
                    self._restore()
            except (HotplateError, *_LINK_ERRORS) as exc:
                log.warning("%s: reconnect %d of %d failed: %s", self.url, attempt, self.config.reconnect_attempts, exc)
                if self._port is not None:
                    self._port.close()
                    self._port = None
                delay = min(2 * delay, self.config.backoff_max_s)
                continue
            self.reconnects += 1
            log.warning("%s: link restored after %d attempt(s)", self.url, attempt)
            return
        raise HotplateError(f"lost the hotplate on {self.url}: {self.config.reconnect_attempts} reconnect attempts "
                            "failed")

    def _restore(self) -> None:
        """Re-send setpoints and switches the app commanded (after a reconnect or a watchdog trip)."""
        t = self.table
        if self._setpoint_c is not None:
            self._exchange_once(t.setpoints["temperature"].encode(self._setpoint_c, self._limit("temperature")))
        if self._setpoint_rpm is not None:
            self._exchange_once(t.setpoints["speed"].encode(self._setpoint_rpm, self._limit("speed")))
        if self._heating:
            self._exchange_once(t.actions["start_heating"])
        if self._stirring:
            self._exchange_once(t.actions["start_stirring"])

    def _watchdog_tripped(self) -> bool:
        """Handle a plate that stopped on its own; return True if the commanded state was restored."""
        self.watchdog_trips += 1
        log.warning("%s: the plate stopped on its own (connection check, 'PC Err')%s", self.url,
                    "; restarting the commanded state" if self.config.restore_on_reconnect else "")
        if self.config.restore_on_reconnect:
            with self._lock:
                self._restore()
            return True
        self._heating = self._stirring = False
        return False

    def _poll_loop(self) -> None:
        while not self._stop.wait(self.config.poll_interval_s):
            try:
                reading = self.read()
            except HotplateError as exc:
                log.error("hotplate poll failed: %s", exc)
                continue
            if self._on_reading is not None:
                self._on_reading(reading)

    def _safe_off(self) -> None:
        errors = []
        for action in ("stop_heating", "stop_stirring"):
            try:
                getattr(self, action)()
            except HotplateError as exc:
                errors.append(str(exc))
        if errors:
            log.error("could not switch the plate off on %s: %s", self.url, "; ".join(errors))

    def _atexit(self) -> None:
        log.warning("process exiting with the hotplate on %s open: switching heating and stirring off", self.url)
        self._stop.set()
        self._safe_off()


NamurHotplate = HeidolphHotplate
"""The same driver under a maker-neutral name, for tables other than Heidolph's (e.g. ``IKA_RCT``)."""
