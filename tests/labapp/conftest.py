"""Shared fixtures of the labapp tests."""
import pytest

from labapp.jobs.demo import simulated_calibration


@pytest.fixture(scope="session")
def sim_calibration(tmp_path_factory):
    """A calibration series of the simulated bench (instant clock): (BenchCalibration, path)."""
    return simulated_calibration(tmp_path_factory.mktemp("simcal"))
