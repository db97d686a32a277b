"""A pyserial stand-in for protocol tests: (sent, reply) byte pairs, consumed in order."""


class ScriptedPort:
    """Each write must equal the next expected bytes; its reply is then what reads return.

    A reply of ``b''`` means the plate stays silent. Tests assert ``not port.pairs`` at the end, so a pair
    left unconsumed fails the test.
    """

    def __init__(self, pairs):
        self.pairs = list(pairs)
        self.pending = b""

    def write(self, data):
        assert self.pairs, f"unexpected write {data!r}"
        sent, reply = self.pairs.pop(0)
        assert data == sent
        self.pending = reply

    def read_until(self, terminator):
        head, sep, self.pending = self.pending.partition(terminator)
        return head + sep

    def reset_input_buffer(self):
        self.pending = b""

    def flush(self):
        pass

    def close(self):
        pass


def scripted_plates(monkeypatch, startup, **driver_kwargs):
    """Generator for a pytest fixture: yields ``make(pairs)``, which returns a connected
    ``HeidolphHotplate(**driver_kwargs)`` on a ScriptedPort expecting ``startup + pairs``; afterwards every
    pair must have been consumed."""
    import atexit

    from drivers.hotplate import HeidolphHotplate, heidolph

    ports, plates = [], []

    def make(pairs):
        port = ScriptedPort(startup + pairs)
        ports.append(port)
        monkeypatch.setattr(heidolph.serial, "serial_for_url", lambda url, **kw: port)
        monkeypatch.setattr(heidolph.time, "sleep", lambda s: None)
        hp = HeidolphHotplate("scripted", keep_alive=False, **driver_kwargs)
        hp.connect()
        plates.append(hp)
        return hp

    yield make
    for hp in plates:
        atexit.unregister(hp._atexit)
    for port in ports:
        assert not port.pairs, f"unconsumed pairs: {port.pairs}"
