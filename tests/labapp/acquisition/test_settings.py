"""The settings' declarations: ranges from the hotplate driver, checks with named messages, the command-line options
made from them, and the run.json layout of the configs (old records still read)."""
import argparse

import pytest

from drivers.hotplate import HEIDOLPH_HEI_TEC, HotplateConfig
from labapp.acquisition.calseries import SeriesConfig
from labapp.acquisition.procedures import RunConfig
from labapp.acquisition.settings import (
    BATH_SETTINGS,
    EXCURSION,
    KEEPALIVE,
    MAX_DURATION,
    OBJECT_MASS,
    ROOM_TEMPERATURE_C,
    SETPOINT,
    STIRRING,
    WATER,
    BathSettings,
    Setting,
    parse_masses,
)
from labapp.cli.argtypes import add_setting, add_settings, setting_values
from labapp.cli.main import build_parser
from labapp.errors import UsageError

#: ``config`` of a run.json written before the bath had its own type: every field at the top level
OLD_RUN_CONFIG = {
    "name": "pill", "interval_s": 11.0, "setpoint_c": 60.0, "speed_rpm": 200.0, "tolerance_c": 0.3, "hold_s": 90.0,
    "heat_timeout_s": 3600.0, "stable_step_s": 5.0, "max_duration_s": 7200.0, "stop_on_steady": True,
    "min_duration_s": 1800.0, "water_g": 450.0, "object_mass_g": 1.7, "object_name": "pill", "notes": "",
    "auto_drop": False, "keepalive_s": 2.0, "frame_bytes_estimate": None, "low_space_bytes": 2000000000,
}
OLD_SERIES_CONFIG = {
    "crop": [100, 200, 160], "name": "calibration", "water_g": 500.0, "grid": 10, "mirror_col": None, "reduce": 2,
    "masses_g": [0.25, 0.5, 1.0], "settle_s": 600.0, "setpoint_c": 70.0, "speed_rpm": 150.0, "tolerance_c": 0.5,
    "hold_s": 120.0, "heat_timeout_s": 7200.0, "stable_step_s": 60.0, "keepalive_s": 2.0,
}


def test_the_hotplate_limits_are_the_drivers():
    plate = HotplateConfig()
    assert (SETPOINT.low, SETPOINT.high) == (ROOM_TEMPERATURE_C,
                                             min(plate.max_temp_c, HEIDOLPH_HEI_TEC.setpoints["temperature"].high))
    assert (STIRRING.low, STIRRING.high) == (0.0, min(plate.max_speed_rpm, HEIDOLPH_HEI_TEC.setpoints["speed"].high))
    assert KEEPALIVE.high == HEIDOLPH_HEI_TEC.watchdog_s and KEEPALIVE.high_open
    with pytest.raises(UsageError, match=r"BathSettings.speed_rpm must be in \[0, 600\] rpm, got 700"):
        BathSettings(speed_rpm=700)           # the driver would refuse it at connect
    with pytest.raises(UsageError, match=r"BathSettings.keepalive_s must be in \(0, 10\) s, got 10"):
        BathSettings(keepalive_s=10)          # the plate's connection check would fire between polls


@pytest.mark.parametrize("config, message", [
    (lambda: RunConfig(object_mass_g=0), r"RunConfig.object_mass_g must be > 0 g, got 0"),
    (lambda: RunConfig(max_duration_s=float("nan")), r"RunConfig.max_duration_s must be > 0 s, got nan"),
    (lambda: RunConfig(frame_bytes_estimate=1.5), r"RunConfig.frame_bytes_estimate must be a whole number > 0 B"),
    (lambda: BathSettings(water_g=-1), r"BathSettings.water_g must be in \[100, 5000\] g, got -1"),
    (lambda: SeriesConfig(crop=(0, 0, 100), settle_s=-1), r"SeriesConfig.settle_s must be >= 0 s, got -1"),
    (lambda: SeriesConfig(crop=(0, 0, 100), grid=0), r"SeriesConfig.grid must be a whole number >= 1, got 0"),
])
def test_each_check_names_the_field_the_value_and_the_range(config, message):
    with pytest.raises(UsageError, match=message):
        config()


def test_the_water_default_is_declared_once():
    from drivers.sim import BenchScene
    from labapp.acquisition.simbench import SCENE, WATER_G

    assert RunConfig().bath.water_g == SeriesConfig(crop=(0, 0, 100)).bath.water_g == WATER_G == WATER.default
    assert SCENE.water_g == WATER.default == BenchScene().water_g   # the renderer (drivers/) keeps the same


def test_a_run_json_written_before_the_bath_type_still_reads():
    config = RunConfig.from_dict(OLD_RUN_CONFIG)
    assert config.bath == BathSettings(water_g=450.0, setpoint_c=60.0, speed_rpm=200.0, tolerance_c=0.3, hold_s=90.0,
                                       heat_timeout_s=3600.0)
    assert config.object_mass_g == 1.7 and config.max_duration_s == 7200.0
    # written in the same layout, with the settings declared since at their defaults
    assert config.to_dict() == {**OLD_RUN_CONFIG, "excursion_c": EXCURSION.default}
    series = SeriesConfig.from_dict(OLD_SERIES_CONFIG)
    assert series.crop == (100, 200, 160) and series.masses_g == (0.25, 0.5, 1.0) and series.bath.stable_step_s == 60
    assert series.to_dict() == {**OLD_SERIES_CONFIG, "excursion_c": EXCURSION.default}


def test_keys_this_version_does_not_know_are_ignored():
    config = RunConfig.from_dict(dict(OLD_RUN_CONFIG, water_g=450.0, another_future_key=True))
    assert config.bath.water_g == 450.0 and config.bath.speed_rpm == OLD_RUN_CONFIG["speed_rpm"]


def test_an_option_is_made_from_its_declaration(capsys):
    parser = argparse.ArgumentParser(prog="t")
    add_setting(parser, MAX_DURATION)
    add_setting(parser, OBJECT_MASS)
    add_settings(parser, BATH_SETTINGS, "bath")
    args = parser.parse_args(["--max-hours", "2", "--setpoint", "55"])
    assert args.max_duration_s == 7200.0 and args.object_mass_g is None      # shown in h, stored in s
    assert BathSettings(**setting_values(args, BATH_SETTINGS)) == BathSettings(setpoint_c=55.0)
    help_text = parser.format_help()
    assert "--stable-step" not in help_text and "--keepalive" not in help_text   # technical: no option
    for argv, says in ((["--setpoint", "150"], "--setpoint: '150': expected a number in [25, 100] C"),
                       (["--rpm", "700"], "--rpm: '700': expected a number in [0, 600] rpm"),
                       (["--max-hours", "0"], "--max-hours: '0': expected a number > 0 h")):
        with pytest.raises(SystemExit) as refused:
            parser.parse_args(argv)
        assert refused.value.code == 2
        assert says in capsys.readouterr().err


def test_sfr_help_shows_unit_default_and_range():
    run = build_parser()._subparsers._group_actions[0].choices["run"].format_help()
    assert "stirring speed, rpm (default 150; in [0, 600] rpm" in " ".join(run.split())
    assert "water in the beaker, g (default 500; in [100, 5000] g" in " ".join(run.split())


def test_a_setting_refuses_a_default_outside_its_range():
    with pytest.raises(ValueError, match="default 5 is not <= 1"):
        Setting("x", "x", default=5, high=1.0)


def test_masses_text():
    assert parse_masses("0.25, 0.5;1") == (0.25, 0.5, 1.0) and parse_masses(" ") == ()
    with pytest.raises(UsageError, match=r"'x' is not a number"):
        parse_masses("0.25, x")
