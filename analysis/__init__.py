"""Pictures and curves to numbers (paper section 4.2): decoding, crop/grid/mirror normalisation,
per-cell Beer-Lambert calibration, concentration estimates, smoothing, run-folder analysis, the
simulation-to-bench calibration (section 4.3), and the release-profile metrics of dissolution testing
(f1/f2, MDT, DE, model fits; replicate units under the regulators' rules, the bootstrap of f2, Tsong's MSD
and Hoffelder's T^2)."""
from analysis.bootstrap import BootstrapF2, bootstrap_f2, f2_estimators
from analysis.calibration import (
                                  BenchCalibration,
                                  ConcentrationEstimate,
                                  estimate_concentration,
                                  fit_bench_calibration,
                                  reanchor_t0,
                                  reference_offset,
)
from analysis.capture_time import capture_time
from analysis.curve import smooth_curve, steady_state
from analysis.decode import decode_image
from analysis.errors import AnalysisError
from analysis.frames import FrameList, read_frame_list
from analysis.geometry import CropGeometry, cell_transmittance, default_geometry, read_cells
from analysis.msd import MsdResult, msd_test
from analysis.profile import (
                                  ReleaseProfile,
                                  Similarity,
                                  dissolution_efficiency,
                                  mean_dissolution_time,
                                  mean_profile,
                                  similarity,
)
from analysis.regulatory import RULE_NAMES, RuleCheck, check_rule
from analysis.release_models import ModelFit, best_fit, fit_release_models
from analysis.replicates import ReplicateSet
from analysis.runfolder import RunCurve, analyze_run, write_cells_csv, write_curve_csv
from analysis.simcal import LooShape, ShapeRun, SimCal, SimCalFit
from analysis.simcal_fit import fit_simcal, leave_one_out

__all__ = [
    "AnalysisError", "BenchCalibration", "BootstrapF2", "ConcentrationEstimate", "CropGeometry", "FrameList",
    "ModelFit", "MsdResult", "ReleaseProfile", "ReplicateSet", "RULE_NAMES", "RuleCheck", "RunCurve", "Similarity",
    "best_fit", "bootstrap_f2", "check_rule", "dissolution_efficiency", "f2_estimators", "fit_release_models",
    "mean_dissolution_time", "mean_profile", "msd_test", "similarity",
    "analyze_run", "capture_time", "cell_transmittance", "decode_image", "default_geometry", "estimate_concentration",
    "fit_bench_calibration", "fit_simcal", "leave_one_out", "LooShape", "read_cells", "read_frame_list",
    "reanchor_t0", "reference_offset", "ShapeRun", "SimCal", "SimCalFit",
    "smooth_curve", "steady_state", "write_cells_csv", "write_curve_csv",
]
