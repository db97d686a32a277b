"""The time left on the command line's progress lines (labapp.cli.eta)."""
from labapp.cli.eta import eta_text


def test_the_time_left_reads_in_seconds_below_a_minute_and_in_tenths_of_minutes_above():
    assert eta_text(None) == "ETA -"
    assert eta_text(44.6) == "ETA 45 s"
    assert eta_text(60.0) == "ETA 1.0 min"
    assert eta_text(83.0) == "ETA 1.4 min"
