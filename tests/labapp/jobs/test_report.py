"""The run report: what it gathers (curve, metrics, f2 under a named rule, criteria, audit, signatures) and a
three-page PDF; the record is not changed."""
import re

import numpy as np
import pytest

from labapp.acquisition.methods import Criterion, load_method, make_method, save_method
from labapp.errors import UsageError
from labapp.jobs.report import collect, write_report
from labapp.records import operators
from labapp.records.runrecord import RecordStatus
from labapp.records.signatures import record_hash, sign
from labapp.records.storage import create_run

MASS_G = 2.0


def _curve_csv(path, k_per_s):
    t = np.arange(0.0, 4 * 3600.0 + 1, 300.0)
    released = MASS_G * (1 - np.exp(-k_per_s * t))
    rows = ["t_s,released_g,released_raw_g"] + [f"{a:.1f},{b:.6f},{b + 0.002 * (-1) ** i:.6f}"
                                                 for i, (a, b) in enumerate(zip(t, released))]
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture
def run_with_method(tmp_path):
    settings = {"water_g": 500.0, "setpoint_c": 37.0, "speed_rpm": 100.0, "tolerance_c": 0.5, "hold_s": 120.0,
                "heat_timeout_s": 7200.0, "interval_s": 300.0, "max_duration_s": 14400.0, "min_duration_s": 1800.0}
    method = load_method(save_method(make_method("IR", settings, acceptance=(
        Criterion("released_percent", 50.0, 80.0, 1.0), Criterion("f2", 50.0))), tmp_path / "ir.json"))
    run = create_run(tmp_path / "data", "pill", {"simulated": True, "object_mass_g": MASS_G, "water_g": 500.0,
                                                  "interval_s": 300.0, "method": method.citation()})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    return run.path, _curve_csv(tmp_path / "curve.csv", 3e-4), _curve_csv(tmp_path / "ref.csv", 2.8e-4)


def test_the_report_gathers_metrics_f2_criteria_and_records(run_with_method):
    folder, curve, ref = run_with_method
    data = collect(folder, references=(ref,), rule="fda", curve=curve)
    expected_1h = 100 * (1 - np.exp(-3e-4 * 3600))                  # 66.0 %
    assert data.acceptance[0] == ("released at 1 h in [50, 80] % of the weighed mass", "PASS", f"{expected_1h:.1f} %")
    [comparison] = data.comparisons
    assert comparison["rule"].agency == "FDA" and comparison["f2"] > 50
    assert data.acceptance[1][1] == "PASS"
    assert data.summary.fits[0].rank == 1 and data.integrity[0] == "sfr verify: OK"
    assert [e["action"] for e in data.audit.entries] == ["start", "complete"]


def test_a_three_page_pdf_and_the_record_untouched(run_with_method, tmp_path):
    folder, curve, ref = run_with_method
    with operators.acting_as("tester"):
        sign(folder, "approved", "tester-password")
    before = record_hash(folder)
    out = write_report(folder, tmp_path / "report.pdf", references=(ref,), curve=curve)
    pdf = out.read_bytes()
    assert pdf.startswith(b"%PDF") and len(re.findall(rb"/Type /Page\b(?!s)", pdf)) == 3
    assert record_hash(folder) == before
    assert collect(folder, curve=curve).signatures[0].intact
    (folder / "events.log").write_text("edited\n")
    assert not collect(folder, curve=curve).signatures[0].intact
    with pytest.raises(UsageError, match="exists"):
        write_report(folder, out, curve=curve)


def test_only_runs_are_reported(tmp_path):
    with pytest.raises(UsageError, match="not a run folder"):
        collect(tmp_path)
    with pytest.raises(UsageError, match="--rule 'xyz'"):
        collect(tmp_path, rule="xyz")


def test_a_curve_the_metrics_refuse_is_still_reported(run_with_method, tmp_path):
    folder, _, _ = run_with_method
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,released_g\n0,0\n300,0.5\n600,0.1\n900,0.6\n")
    data = collect(folder, curve=bad)
    assert data.summary is None and "must not decrease" in data.metrics_error
    assert write_report(folder, tmp_path / "bad.pdf", curve=bad).is_file()
