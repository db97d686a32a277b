"""`sfr design --physical-correction`, `--correction-rounds` and `--w-channel` reach the design configuration; a bad
choice is one clear error from it."""
import argparse

import pytest

from design.errors import DesignError
from design.inverse.config import DesignConfig
from labapp.cli.commands import design as command


def _options(*argv: str) -> dict:
    parser = argparse.ArgumentParser()
    command.add_arguments(parser)
    return command._given_options(parser.parse_args(["--target", "sphere", "--out", "x", *argv]))


def test_the_correction_flags_become_design_settings():
    options = _options("--physical-correction", "none", "--correction-rounds", "3")
    assert options["physical_correction"] == "none" and options["correction_rounds"] == 3
    assert DesignConfig(**options).physical_correction == "none"
    left_out = _options()
    assert "physical_correction" not in left_out and "correction_rounds" not in left_out
    assert DesignConfig(**left_out).physical_correction == "defect"  # the default for nfc


def test_an_unknown_correction_is_refused_by_the_design_configuration():
    with pytest.raises(DesignError, match="physical_correction must be one of"):
        DesignConfig(**_options("--physical-correction", "finer"))


def test_the_channel_weight_becomes_a_design_setting():
    from design.inverse.settings import W_CHANNEL

    options = _options("--w-channel", "40")
    assert options["w_channel"] == 40.0
    assert DesignConfig(**options, swelling_mm=0.6).w_channel == 40.0
    assert DesignConfig(**_options(), swelling_mm=0.6).w_channel == W_CHANNEL
    with pytest.raises(DesignError, match="w_channel"):   # a weight without a swelling width has nothing to keep open
        DesignConfig(**options)
