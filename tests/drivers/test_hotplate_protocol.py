"""Heidolph protocol as (sent, reply) byte pairs; a test fails if pairs remain unconsumed."""
import pytest

from drivers.hotplate import HEIDOLPH_HEI_TEC, HotplateConfig, HotplateError
from tests.drivers.scripted_port import scripted_plates

FAST = HotplateConfig(timeout_s=0.2, backoff_s=0.1, retries=1)
STARTUP = [(b"PA_NEW\r\n", b"PA_NEW\n\r"), (b"CC_ON\r\n", b"CC_ON\r\n")]


@pytest.fixture
def plate(monkeypatch):
    """Returns a factory: plate(pairs) -> connected driver; checks all pairs were consumed."""
    yield from scripted_plates(monkeypatch, STARTUP, config=FAST)


READ = [(b"IN_PV_1\r\n", b"IN_PV_1 69.8\r\n"), (b"IN_PV_3\r\n", b"IN_PV_3 73.1\r\n"),
        (b"IN_PV_5\r\n", b"IN_PV_5 150\r\n"), (b"IN_SP_1\r\n", b"IN_SP_1 70.0\r\n"),
        (b"IN_SP_3\r\n", b"IN_SP_3 150\r\n")]


def test_setpoints_and_switches_are_sent_as_documented(plate):
    hp = plate([(b"OUT_SP_1 70.0\r\n", b"OUT_SP_1 70.0\r\n"), (b"OUT_SP_3 150\r\n", b"OUT_SP_3 150\r\n"),
                (b"START_1\r\n", b"START_1\r\n"), (b"START_2\r\n", b"START_2\r\n")]
               + READ + [(b"STATUS\r\n", b"STATUS 1\r\n")])
    hp.set_temperature(70)
    hp.set_speed(150)
    hp.start_heating()
    hp.start_stirring()
    r = hp.read()
    assert (r.probe_c, r.plate_c, r.speed_rpm, r.setpoint_c, r.setpoint_rpm) == (69.8, 73.1, 150, 70, 150)
    assert r.heating and r.stirring


def test_no_probe_reads_as_none(plate):
    hp = plate([(b"IN_PV_1\r\n", b"IN_PV_1 999.9\r\n")] + READ[1:] + [(b"STATUS\r\n", b"STATUS 0\r\n")])
    assert hp.read().probe_c is None


@pytest.mark.parametrize("call, value, match", [
    ("set_temperature", 150.0, r"OUT_SP_1: 150.0 C is outside the allowed range \[0, 100\] C"),
    ("set_temperature", -5.0, r"outside the allowed range"),
    ("set_temperature", float("nan"), r"outside the allowed range"),
    ("set_speed", 2000.0, r"OUT_SP_3: 2000.0 rpm is outside the allowed range \[0, 600\] rpm"),
])
def test_client_side_limits_refuse_before_the_wire(plate, call, value, match):
    hp = plate([])
    with pytest.raises(HotplateError, match=match):
        getattr(hp, call)(value)


def test_garbage_reply_is_retried(plate):
    hp = plate([(b"STOP_1\r\n", b"#k2!x\r\n"), (b"STOP_1\r\n", b"STOP_1\r\n")])
    hp.stop_heating()


def test_persistent_garbage_is_a_clear_error(plate):
    hp = plate([(b"START_1\r\n", b"zz\r\n"), (b"START_1\r\n", b"IN_PV_3 20.0\r\n")])
    with pytest.raises(HotplateError, match=r"no valid reply to 'START_1' after 2 attempts"):
        hp.start_heating()


def test_silence_is_a_clear_error(plate):
    hp = plate([(b"IN_SP_1\r\n", b""), (b"IN_SP_1\r\n", b"")])
    with pytest.raises(HotplateError, match=r"scripted: no valid reply to 'IN_SP_1'.*within 0.2 s"):
        hp._exchange("IN_SP_1")


def test_negative_status_names_the_device_error(plate):
    hp = plate(READ + [(b"STATUS\r\n", b"STATUS -1\r\n")])
    with pytest.raises(HotplateError, match=r"scripted: remote control blocked"):
        hp.read()


def test_close_switches_heating_and_stirring_off(plate):
    hp = plate([(b"STOP_1\r\n", b"STOP_1\r\n"), (b"STOP_2\r\n", b"STOP_2\r\n")])
    hp.close()


@pytest.mark.parametrize("kwargs, match", [
    ({"pace_s": 0.05}, r"pace_s must be >= 0.1 s"),
    ({"max_temp_c": 400}, r"max_temp_c must be in \(0, 300\]"),
    ({"poll_interval_s": 12}, r"poll_interval_s must be in \(0, 10.0\)"),
    ({"retries": -1}, r"retries must be >= 0"),
])
def test_config_is_checked(kwargs, match):
    with pytest.raises(ValueError, match=match):
        HotplateConfig(**kwargs)


def test_table_reply_and_payload_round_trip():
    t = HEIDOLPH_HEI_TEC
    assert t.payload("OUT_SP_1 70.0", t.reply("OUT_SP_1 70.0", "70.0")) == "70.0"
    assert t.payload("START_1", "START_1\n\r") == ""
    with pytest.raises(HotplateError, match=r"does not echo command 'IN_PV_1'"):
        t.payload("IN_PV_1", "IN_PV_3 20.0")
