"""Setting up an inverse-design problem: configuration, domain, design space and target curve.

A target spec is one of: a sample shape name (`design.geometry.shapes.SAMPLE_SHAPES`), a mesh file
(.stl/.obj/.ply/.off/.3mf), a ``tau_mm,released_mm3`` CSV, or an analytic family
``zero-order[:final=F,duration=D]`` / ``accel:q=Q[,final=F,duration=D]`` with F the total release
as a fraction of the domain volume and D the release's end as a fraction of T (Fig. 7).

A source shape's target is its physical release, by exact surface distances
(`design.forward.reference`), not its release on the design grid: the design grid's first-order error
depends on the shape, and a print is judged against what the source itself releases.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from design._validate import MESH_SUFFIXES
from design.errors import DesignError
from design.fabrication.connectivity import TAIL_SLOPE
from design.fabrication.extract import count_pieces
from design.fabrication.ico import DEFAULT_COARSEN, DEFAULT_LAYERS, IcoConfig
from design.forward.reference import design_lattice, reference_release
from design.forward.simulator import total_time
from design.geometry.shapes import SAMPLE_SHAPES, sample_shape
from design.geometry.voxelize import voxelize
from design.inverse.lbfgs import LINE_SEARCHES
from design.inverse.presets import preset_values
from design.inverse.rate import RATE_SPAN_MIN_VOX, middle_span_mm
from design.inverse.spaces import BUILD_AXIS, SPACE_CHOICES, DesignSpace, SpaceRequest, build_space
from design.inverse.targets import (
    Feasibility,
    Target,
    check_feasibility,
    constant_acceleration,
    curve_end_mm,
    target_from_curve,
    tau_grid,
)

log = logging.getLogger(__name__)

DEFAULT_DOMAIN_MM = 20.0
"""Edge of the cubic domain used when the target has no source mesh and no --domain-mm, mm."""
CSV_HORIZON_MARGIN = 1.1
"""A CSV target's default cube has a half-edge (about its horizon T) this much above the curve's end."""

# Hyperparameters per design space (the paper's Tables 1-2: w_b 20-50, r 4-5, beta 3 for the
# source-shape designs of Fig. 6). NFC uses the ICO column without the ICO term.
SPACE_DEFAULTS: dict[str, dict[str, float]] = {
    "nfc": {"w_binary": 20.0, "beta": 3.0, "beta_final": 12.0},
    "extruded": {"w_binary": 30.0, "beta": 3.0, "beta_final": 12.0},
    "ico": {"w_binary": 30.0, "beta": 3.0, "w_fab": 3000.0},
}
"""`DesignConfig` defaults per design space: the J_binary weight w_b, the projection steepness beta
at the start and, where it differs, at the end of the run (``beta_final``; equal to ``beta``: fixed),
and for ICO the weight w_f of J_fab normalised to 1 at the start design (`design.fabrication.ico`).
Why NFC and extruded designs raise beta from 3 to 12: docs/design.md#beta-continuation; why w_b is
30 rather than 20 for extruded and ICO designs: docs/design.md#j_binary-weight-per-space; why w_f is
3000 rather than the paper's 50-200: docs/design.md#ico-weight-w_f."""
DEFAULT_RADIUS_MM = 1.0
"""Smoothing radius r when none is given, mm: about the paper's r = 4 voxels on its sample grids,
fixed in mm so that the minimum feature (about r, five 0.2 mm print lines, section 4.1) does not
shrink as the resolution grows (docs/design.md#smoothing-radius-in-mm)."""
W_CONNECT = 5.0
"""Default weight of the connectivity penalty J_conn (`design.fabrication.connectivity`), which holds a
design to one printable piece (docs/design.md#one-printable-piece)."""
W_CHANNEL = 100.0
"""Default weight of the channel-width term J_chan (`design.fabrication.channels`) when the print swells
(`DesignConfig.swelling_mm` > 0; 0 otherwise): the optimiser keeps the open channels at least the swelling width
wide, so that the fill of the outputs has little or nothing left to change (docs/design.md#minimum-open-channel-width)."""
START_FILL = 2.0 / 3.0
"""Density of the compact start of an extruded design (`start_regions`): a target without a source starts
at it, and a start is hollowed only as far as its band still holds the target's volume at it."""
MULTISTART_STARTS = 4
MULTISTART_MIN_RESOLUTION = 128
MULTISTART_SPACES = ("nfc", "extruded")
"""Default multi-start (`DesignConfig.starts`): 4 seeded starts at half the resolution, then the best
refined, for nfc and extruded designs of a source shape at resolution 128 or finer; ICO designs and curve
targets in nfc keep one start. Why: docs/design.md#multi-start."""
CURVE_EXTRUDED_STARTS = 3
"""Default starts of an extruded design of a curve target (`DesignConfig.starts`): its three start outlines, a
square, a cross and a ring (`start_regions`; noisy squares in place of those that do not fit), each a whole run
below `MULTISTART_MIN_RESOLUTION`, the one whose print fits best kept (docs/design.md#multi-start)."""
OPTIMIZERS = ("lbfgs", "LD_LBFGS", "LD_MMA", "LD_CCSAQ")
"""`DesignConfig.optimizer` choices: `design.inverse.lbfgs` (default) and three nlopt algorithms."""
ANALYTIC_W_RATE = 1.0
"""Default weight of the rate-fit term J_rate for analytic (zero-order / accel) targets; 0 for the
others, whose curves come from shapes or measurements
(docs/design.md#analytic-targets-rate-term-robust-formulation-beta-64)."""
PHYSICAL_CORRECTIONS = ("defect", "none")
"""`DesignConfig.physical_correction` choices: "defect", the defect-correction rounds of `design.inverse.defect`
that aim the print's release, judged by the reference evaluator, at the target; "none", the design grid's
release alone (as in the paper). Why "defect" is the default: docs/design.md#physical-correction."""
CORRECTION_SPACES = ("nfc", "extruded")
"""The design spaces whose runs correct the print by default (`DesignConfig.physical_correction` None); ICO
runs, whose evaluations carry the elasticity solves, default to "none"."""
CORRECTION_ROUNDS = 2
"""Default defect-correction rounds (`DesignConfig.correction_rounds`)."""
CORRECTION_EVALS_SHARE = 0.1
"""Default evaluations of each correction round, as a share of `DesignConfig.max_iter` (at least 1)."""
ANALYTIC_DEFAULTS: dict[str, dict[str, float]] = {
    "nfc": {"robust_eta": 0.1, "beta_final": 64.0},
    "extruded": {"robust_eta": 0.1, "beta_final": 64.0, "w_connect": 10.0},
}
"""Defaults for analytic targets, per design space, over `SPACE_DEFAULTS` and `W_CONNECT`: the robust
formulation's threshold offset (0, one design as in the paper, for the other targets; it needs
w_rate > 0), the final beta of the continuation and, for extruded designs, the connectivity weight.
ICO designs keep their `SPACE_DEFAULTS`. Why: the robust formulation makes a design that relies on
grey layers narrower than the smoothing radius pay for them, and in the extruded space it needs the
higher J_conn weight to keep a nested target in one piece
(docs/design.md#analytic-targets-rate-term-robust-formulation-beta-64)."""


@dataclass(frozen=True)
class DesignConfig:
    """Everything a design run depends on; stored as ``config.json`` in the run folder.

    Parameters
    ----------
    target : str
        Target spec (see module docstring).
    space : str
        Design space name ("nfc", "extruded", "ico").
    resolution : int
        Voxels along the full domain's longest side (even, >= 8).
    domain_mm : tuple of 3 float or None
        Full domain size (x, y, z), mm; None = the source's bounding box plus ``margin`` on every
        side (cubic for nfc), or a `DEFAULT_DOMAIN_MM` cube for targets without a source.
    height_mm : float or None
        Extrusion height, mm (extruded only); None = ``height_fraction`` of the domain's longest
        side if given, else the source's height, else the domain's.
    height_fraction : float or None
        Extrusion height as a fraction of the domain's longest side (set by the paper presets).
    preset : str or None
        ``paper:NAME``: hyperparameters of the paper's Table 1 or 2 (`design.inverse.presets`) for the
        fields left None; explicit values win.
    w_binary, radius_vox, beta : float or None
        Eq. (4) hyperparameters; None = the preset's, else `SPACE_DEFAULTS` (resolved and stored
        explicitly). The
        smoothing radius r is in voxels; give it in mm with ``radius_mm`` instead.
    radius_mm : float or None
        Smoothing radius r in mm (exclusive with ``radius_vox``); with neither,
        `DEFAULT_RADIUS_MM`. Converted to voxels of the design grid (at least 1) by `prepare`.
    allow_pieces : bool
        Drop the connectivity penalty: the design may fall apart into pieces (as in the paper).
    w_connect : float or None
        Weight of the connectivity penalty J_conn (`design.fabrication.connectivity`) unless ``allow_pieces``;
        None = `ANALYTIC_DEFAULTS` for analytic targets, else `W_CONNECT`.
    connect_planes : bool
        J_conn also measures paths to the mirror planes (its plane term); runs stored before the
        term resume without it.
    connect_tail : float
        Slope of J_conn's tail (`design.fabrication.connectivity.TAIL_SLOPE`); runs stored before the tail
        resume without it (0).
    starts : int or None
        Seeded starts (`design.inverse.multistart`): from resolution `MULTISTART_MIN_RESOLUTION` on run at half
        the resolution, the best refined at full resolution; below it each a whole run, the one whose print
        fits best kept. 1 = a single run from the start design. None = `MULTISTART_STARTS` for nfc and extruded
        designs of a source shape at resolution `MULTISTART_MIN_RESOLUTION` or finer,
        `CURVE_EXTRUDED_STARTS` for extruded designs of a curve target, else 1.
    w_fab : float or None
        Weight w_f of the space's fabrication term (ico only; None = preset or `SPACE_DEFAULTS`,
        0 for spaces without one).
    layers : int
        L, partial designs of the ICO term (section 3.6).
    ico_coarsen : int
        Design voxels per elasticity element edge of the ICO term (`design.fabrication.ico`).
    stiffness_law : str
        "simp" (p = 3) or "ramp" (q = 3) moduli of the ICO term.
    rate_window_vox : float
        Finite-difference span of J_rate's rates, voxel edges (rounded to whole tau samples).
    beta_final : float or None
        Beta continuation: raise beta geometrically from ``beta`` to ``beta_final`` over
        `design.inverse.optimize.BETA_STAGES` equal stages of the run; equal to ``beta``: fixed, as in the
        paper. None = the preset's, else `ANALYTIC_DEFAULTS` for analytic targets, else
        `SPACE_DEFAULTS` (at least ``beta``), else fixed.
    w_rate : float or None
        Weight of the rate-fit term J_rate (`design.inverse.rate`); None = `ANALYTIC_W_RATE` for analytic
        targets, 0 (eq. 4 as in the paper) otherwise.
    rate_span : (float, float)
        J_rate compares rates only between the times the target reaches these fractions of its
        final release (`design.inverse.rate`); (0, 1) = the whole curve.
    robust_eta : float or None
        Threshold offset d of the robust formulation (`design.inverse.objective`): the designs projected at
        1/2 - d and 1/2 + d must release with the target's rate profile too; 0 = off (as in the
        paper). Three simulations per evaluation; needs w_rate > 0. None = `ANALYTIC_DEFAULTS` for
        analytic targets whose w_rate > 0, else 0.
    max_iter : int
        Maximum objective evaluations (paper: 500).
    optimizer : str
        One of `OPTIMIZERS` (see `design.inverse.optimize`).
    ftol_rel, xtol_rel : float
        Relative tolerances on J and on the variables (0 disables; by default only the
        iteration limit and a stalled line search end a run).
    lbfgs_memory : int
        L-BFGS correction pairs m (memory O(m N)).
    line_search : str
        The "lbfgs" optimiser's line-search rule, one of `design.inverse.lbfgs.LINE_SEARCHES`: "luksan"
        (default; nlopt LD_LBFGS's rule) or "strong-wolfe".
    bounds : str
        "cosine" (rho_hat = (1 - cos z) / 2, unconstrained L-BFGS) or "box" (nlopt box bounds, not
        with the "lbfgs" optimiser); see `design.inverse.optimize`.
    checkpoint_every : int
        Evaluations between checkpoints.
    margin : float
        Empty space around a source mesh, as a fraction of its largest extent.
    warn_channel_mm : float
        Warn when the narrowest open channel is below this, mm.
    allow_infeasible : bool
        Optimise even when the feasibility check fails.
    samples : int
        Points of the tau grid (1001 gives dtau = T/1000, section 3.4).
    formats : tuple of str
        Mesh formats to export besides STL ("3mf", "obj").
    physical_correction : str or None
        One of `PHYSICAL_CORRECTIONS`: how the run makes its print's true release meet the target. None =
        "defect" in `CORRECTION_SPACES`, else "none".
    correction_rounds : int
        Defect-correction rounds after the optimisation (`design.inverse.defect`), 1 to 10.
    correction_evals : int or None
        Objective evaluations of each round, part of ``max_iter``; None = `CORRECTION_EVALS_SHARE` of ``max_iter``
        (at least 1).
    anisotropy : float
        Print physics (a simulation calibration's, ``sfr design --simcal``): erosion speed along z (the build
        direction) over the in-plane speed in the forward model; 1 = the paper's isotropic model.
    print_offset_mm : float
        Print physics: the print comes out this much larger (smaller if negative) than its mesh, mm. The run
        designs the solid that must come out and writes ``design.stl`` shrunk by it (`design.files.outputs`).
    swelling_mm : float
        Print physics: channels narrower than this are shut in the forward model until their walls dissolve
        (`design.forward.swelling`), and it is the minimum open channel width of the print, enforced by the
        correction stage of the outputs (narrower channels are filled), mm; 0 = none.
    w_channel : float or None
        Weight of the channel-width term J_chan (`design.fabrication.channels`), which holds the optimised design's
        open channels to at least ``swelling_mm``; None = `W_CHANNEL` when ``swelling_mm`` > 0 (resolved), else no
        term (None stays, so that a configuration given print physics later gets the default). Runs stored before
        the term resume without it (0).

    With swelling the physical correction is off by default (``physical_correction`` None resolves to "none"),
    and "defect" is refused: its reference evaluator has the print's anisotropy but does not shut channels. The
    print offset does not enter it: the designed solid is the print (the STL is it shrunk by the offset).
    """

    target: str
    space: str = "nfc"
    resolution: int = 64
    domain_mm: tuple[float, float, float] | None = None
    height_mm: float | None = None
    height_fraction: float | None = None
    preset: str | None = None
    w_binary: float | None = None
    radius_vox: float | None = None
    radius_mm: float | None = None
    allow_pieces: bool = False
    w_connect: float | None = None
    connect_planes: bool = True
    connect_tail: float = TAIL_SLOPE
    starts: int | None = None
    beta: float | None = None
    w_fab: float | None = None
    layers: int = DEFAULT_LAYERS
    ico_coarsen: int = DEFAULT_COARSEN
    stiffness_law: str = "simp"
    beta_final: float | None = None
    rate_window_vox: float = 1.0
    w_rate: float | None = None
    rate_span: tuple[float, float] = (0.05, 0.95)
    robust_eta: float | None = None
    max_iter: int = 500
    optimizer: str = "lbfgs"
    ftol_rel: float = 0.0
    xtol_rel: float = 0.0
    lbfgs_memory: int = 10
    line_search: str = LINE_SEARCHES[0]
    bounds: str = "cosine"
    checkpoint_every: int = 10
    margin: float = 0.25
    warn_channel_mm: float = 1.0
    allow_infeasible: bool = False
    samples: int = 1001
    formats: tuple[str, ...] = ()
    physical_correction: str | None = None
    correction_rounds: int = CORRECTION_ROUNDS
    correction_evals: int | None = None
    anisotropy: float = 1.0
    print_offset_mm: float = 0.0
    swelling_mm: float = 0.0
    w_channel: float | None = None

    def __post_init__(self) -> None:
        if self.space not in SPACE_CHOICES:
            raise DesignError(f"space must be one of {SPACE_CHOICES}, got {self.space!r}")
        presets = [preset_values(self.preset, self.space)] if self.preset is not None else []
        is_analytic = _parse_analytic(self.target) is not None
        analytic = ANALYTIC_DEFAULTS.get(self.space, {}) if is_analytic else {}
        space_defaults = {**SPACE_DEFAULTS.get(self.space, {}), **analytic}
        space_defaults.pop("robust_eta", None)  # resolved below, once w_rate is known
        for values in presets + [space_defaults, {"w_fab": 0.0, "w_connect": W_CONNECT}]:
            for key, value in values.items():
                if getattr(self, key) is None and not (key == "radius_vox" and self.radius_mm is not None):
                    object.__setattr__(self, key, max(value, self.beta) if key == "beta_final" else value)
        if self.w_fab < 0 or (self.w_fab > 0 and self.space != "ico"):
            raise DesignError(f"w_fab must be >= 0, and only the ico space has a fabrication term; got "
                              f"{self.w_fab} for space {self.space!r}")
        if self.height_fraction is not None and not 0 < self.height_fraction <= 1:
            raise DesignError(f"height_fraction must be in (0, 1], got {self.height_fraction}")
        IcoConfig(self.layers, self.ico_coarsen, self.stiffness_law)  # checks the ICO settings
        if self.w_rate is None:
            object.__setattr__(self, "w_rate", ANALYTIC_W_RATE if is_analytic else 0.0)
        if self.w_rate < 0 or not 0 < self.rate_window_vox <= 64:
            raise DesignError(f"w_rate must be >= 0 and rate_window_vox in (0, 64]; got {self.w_rate}, "
                              f"{self.rate_window_vox}")
        if len(self.rate_span) != 2 or not 0.0 <= self.rate_span[0] < self.rate_span[1] <= 1.0:
            raise DesignError(f"rate_span must be two fractions 0 <= lo < hi <= 1, got {self.rate_span}")
        if self.robust_eta is None:
            object.__setattr__(self, "robust_eta", analytic.get("robust_eta", 0.0) if self.w_rate > 0 else 0.0)
        if not 0.0 <= self.robust_eta <= 0.4:
            raise DesignError(f"robust_eta must be in [0, 0.4], got {self.robust_eta}")
        if self.robust_eta > 0 and not self.w_rate > 0:
            raise DesignError("the robust formulation compares release rates: it needs w_rate > 0")
        if self.resolution < 8 or self.resolution % 2:
            raise DesignError(f"resolution must be an even number >= 8 voxels, got {self.resolution}")
        if self.domain_mm is not None and (len(self.domain_mm) != 3 or min(self.domain_mm) <= 0):
            raise DesignError(f"domain must be three positive sizes in mm, got {self.domain_mm}")
        if self.height_mm is not None and not self.height_mm > 0:
            raise DesignError(f"extrusion height must be > 0 mm, got {self.height_mm}")
        if self.w_binary is not None and self.w_binary < 0:
            raise DesignError(f"w_binary must be >= 0, got {self.w_binary}")
        if self.radius_vox is not None and not 1.0 <= self.radius_vox <= 32.0:
            raise DesignError(f"smoothing radius must be in [1, 32] voxels, got {self.radius_vox}")
        if self.radius_vox is not None and self.radius_mm is not None:
            raise DesignError(f"give the smoothing radius in voxels ({self.radius_vox}) or in mm "
                              f"({self.radius_mm}), not both")
        if self.radius_mm is not None and not self.radius_mm > 0:
            raise DesignError(f"smoothing radius must be > 0 mm, got {self.radius_mm}")
        if not self.w_connect >= 0:
            raise DesignError(f"w_connect must be >= 0, got {self.w_connect}")
        if not self.connect_tail >= 0:
            raise DesignError(f"connect_tail must be >= 0, got {self.connect_tail}")
        if self.starts is None:
            shape = _is_shape_target(self.target)
            multi = self.space in MULTISTART_SPACES and self.resolution >= MULTISTART_MIN_RESOLUTION and shape
            outlines = self.space == "extruded" and not shape
            object.__setattr__(self, "starts", MULTISTART_STARTS if multi else CURVE_EXTRUDED_STARTS if outlines
                               else 1)
        if not 1 <= self.starts <= 64:
            raise DesignError(f"starts must be in [1, 64], got {self.starts}")
        if self.beta is not None and not 0 < self.beta <= 64:
            raise DesignError(f"beta must be in (0, 64], got {self.beta}")
        if self.beta_final is not None and not self.beta <= self.beta_final <= 64:
            raise DesignError(f"beta_final must be in [beta, 64] = [{self.beta}, 64], got {self.beta_final}")
        if self.max_iter < 1 or self.checkpoint_every < 1 or not 1 <= self.lbfgs_memory <= 100:
            raise DesignError(f"need max_iter >= 1, checkpoint_every >= 1, lbfgs_memory in [1, 100]; got "
                              f"{self.max_iter}, {self.checkpoint_every}, {self.lbfgs_memory}")
        if not 0 <= self.margin <= 2 or not self.warn_channel_mm > 0 or self.samples < 3:
            raise DesignError(f"need margin in [0, 2], warn_channel_mm > 0, samples >= 3; got {self.margin}, "
                              f"{self.warn_channel_mm}, {self.samples}")
        if self.bounds not in ("cosine", "box"):
            raise DesignError(f"bounds must be 'cosine' or 'box', got {self.bounds!r}")
        if self.optimizer not in OPTIMIZERS:
            raise DesignError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if self.line_search not in LINE_SEARCHES:
            raise DesignError(f"line_search must be one of {LINE_SEARCHES}, got {self.line_search!r}")
        if self.optimizer == "lbfgs" and self.bounds != "cosine":
            raise DesignError("the 'lbfgs' optimiser is unconstrained: it needs bounds='cosine' (box bounds: "
                              "choose an nlopt optimizer)")
        if not (np.isfinite(self.anisotropy) and 0.1 <= self.anisotropy <= 10.0):
            raise DesignError(f"anisotropy must be in [0.1, 10], got {self.anisotropy}")
        if not (np.isfinite(self.print_offset_mm) and abs(self.print_offset_mm) <= 5.0):
            raise DesignError(f"print_offset_mm must be a finite number within +-5 mm, got {self.print_offset_mm}")
        if not (np.isfinite(self.swelling_mm) and 0.0 <= self.swelling_mm <= 10.0):
            raise DesignError(f"swelling_mm must be in [0, 10] mm, got {self.swelling_mm}")
        if self.w_channel is None and self.swelling_mm > 0:
            object.__setattr__(self, "w_channel", W_CHANNEL)
        if self.w_channel is not None and (isinstance(self.w_channel, bool) or not isinstance(self.w_channel, (int, float))
                                           or not (np.isfinite(self.w_channel) and self.w_channel >= 0)):
            raise DesignError(f"w_channel must be a finite number >= 0, got {self.w_channel!r}")
        if self.w_channel and not self.swelling_mm > 0:
            raise DesignError(f"w_channel = {self.w_channel:g} weighs the minimum open channel width, which is "
                              "swelling_mm: it needs swelling_mm > 0")
        if self.physical_correction is None:
            object.__setattr__(self, "physical_correction",
                               PHYSICAL_CORRECTIONS[0] if self.space in CORRECTION_SPACES and not self.swelling_mm > 0
                               else "none")
        if self.physical_correction == "defect" and self.swelling_mm > 0:
            raise DesignError(f"physical_correction 'defect' judges the print by the reference evaluator, which does "
                              f"not shut channels narrower than swelling_mm ({self.swelling_mm:g} mm); use 'none' "
                              f"with swelling")
        if self.physical_correction not in PHYSICAL_CORRECTIONS:
            raise DesignError(f"physical_correction must be one of {PHYSICAL_CORRECTIONS}, got "
                              f"{self.physical_correction!r}")
        if self.correction_evals is None:
            object.__setattr__(self, "correction_evals", max(1, int(round(CORRECTION_EVALS_SHARE * self.max_iter))))
        if not 1 <= self.correction_rounds <= 10 or not self.correction_evals >= 1:
            raise DesignError(f"need correction_rounds in [1, 10] and correction_evals >= 1; got "
                              f"{self.correction_rounds}, {self.correction_evals}")
        bad = set(self.formats) - {"3mf", "obj"}
        if bad:
            raise DesignError(f"extra mesh formats must be among 3mf, obj; got {sorted(bad)}")


@dataclass(frozen=True)
class Problem:
    """A prepared design problem.

    Attributes
    ----------
    space : DesignSpace
    target : Target
    feasibility : Feasibility
    dx_mm : float
    origin_mm : (3,) ndarray of float
        Corner of the full design grid, mm (voxel i spans origin + [i, i+1) dx).
    full_shape : tuple of 3 int
        Voxels of the full (unfolded) simulated object.
    source_solid : ndarray of bool or None
        The source mesh voxelised on the full design grid (for the recovery check).
    radius_vox : float
        Smoothing radius r on this grid, voxels (`DesignConfig.radius_vox` or its ``radius_mm``).
    start_regions : tuple of (ndarray of bool or None)
        Where the start designs hold material (`start_regions`), the default first; None = the whole domain.
    warnings : tuple of str
        What is known about the source and the target before the run (`source_warnings`,
        `rate_resolution_warnings`); logged when the problem is prepared and kept in the run's summary.
    source_mesh : trimesh.Trimesh or None
        The source mesh of a mesh target, mm.
    target_error_mm3 : float or None
        The stated error of a mesh target's release by the reference evaluator
        (`design.forward.reference.ReferenceRelease.error_mm3`), mm^3; None for other targets.
    """

    space: DesignSpace
    target: Target
    feasibility: Feasibility
    dx_mm: float
    origin_mm: np.ndarray
    full_shape: tuple[int, int, int]
    source_solid: np.ndarray | None
    radius_vox: float
    start_regions: tuple[np.ndarray | None, ...] = (None,)
    warnings: tuple[str, ...] = ()
    source_mesh: trimesh.Trimesh | None = None
    target_error_mm3: float | None = None

    @property
    def start_region(self) -> np.ndarray | None:
        """Where a single run's start design holds material: the first of `start_regions`."""
        return self.start_regions[0]


def source_warnings(source_solid: np.ndarray | None, allow_pieces: bool) -> tuple[str, ...]:
    """Warnings about a voxelised source: several separate pieces where the design must be one."""
    if source_solid is None or allow_pieces:
        return ()
    pieces = count_pieces(source_solid)
    if pieces < 2:
        return ()
    return (f"the source is {pieces} separate pieces and the design is held to one piece, so it cannot take "
            "the source's own shape; allow pieces (--allow-pieces) to let it",)


def rate_resolution_warnings(target: Target, dx_mm: float, w_rate: float, resolution: int) -> tuple[str, ...]:
    """Warnings about a rate-fitted target whose middle 80% spans too few voxels of tau to be measured.

    Below `design.inverse.rate.RATE_SPAN_MIN_VOX` the grid's own error in the rate deviation reaches several
    points; the warning names the resolution at which the span reaches it.
    """
    if not w_rate > 0 or not target.final_mm3 > 0:
        return ()
    lo, hi = middle_span_mm(target.tau_mm, target.released_mm3)
    span_vox = (hi - lo) / dx_mm
    if span_vox >= RATE_SPAN_MIN_VOX:
        return ()
    needed = _even_ceil(resolution * RATE_SPAN_MIN_VOX / span_vox)
    return (f"the target's middle 80% (10% to 90% released) spans {span_vox:.1f} voxels of tau at resolution "
            f"{resolution}: too few to measure a release rate to better than a few points, so the design's rate "
            f"deviation is that uncertain; at about resolution {needed} it spans {RATE_SPAN_MIN_VOX:g}",)


def _parse_analytic(spec: str) -> tuple[float, float, float] | None:
    head, _, tail = spec.partition(":")
    if head not in ("zero-order", "accel"):
        return None
    params = {"q": 1.0, "final": 0.15, "duration": 0.2}
    for item in filter(None, tail.split(",")):
        key, _, value = item.partition("=")
        if key not in params:
            raise DesignError(f"unknown analytic target parameter {key!r} in {spec!r}; use q, final, duration")
        try:
            params[key] = float(value)
        except ValueError as exc:
            raise DesignError(f"bad value {value!r} for {key} in target {spec!r}") from exc
    if head == "zero-order":
        params["q"] = 1.0
    return params["q"], params["final"], params["duration"]


def _is_shape_target(spec: str) -> bool:
    """Whether a target spec names a source shape (a sample shape or a mesh file), not a curve."""
    return spec in SAMPLE_SHAPES or Path(spec).suffix.lower() in MESH_SUFFIXES


def target_file(spec: str) -> str | None:
    """What file a target spec names: "mesh" (a mesh file), "csv" (a ``tau_mm,released_mm3`` curve) or None
    (a sample shape or an analytic family, which need no file)."""
    if spec in SAMPLE_SHAPES:
        return None
    if _is_shape_target(spec):
        return "mesh"
    if _parse_analytic(spec) is None and spec.lower().endswith(".csv"):
        return "csv"
    return None


def _source_mesh(spec: str, mesh: trimesh.Trimesh | None) -> trimesh.Trimesh | None:
    """The source shape of a sample-shape or mesh-file target (the latter as loaded), else None."""
    if spec in SAMPLE_SHAPES:
        return sample_shape(spec)
    if _is_shape_target(spec):
        if mesh is None:
            raise DesignError(f"target {spec!r} is a mesh file: load it with design.files.targets_io.load_problem")
        return mesh
    return None


def _even_ceil(x: float) -> int:
    return max(2, 2 * int(np.ceil(x / 2.0 - 1e-9)))


def _curve_target(config: DesignConfig, analytic: tuple[float, float, float] | None,
                  curve: tuple[np.ndarray, np.ndarray] | None, t_mm: float, box_volume_mm3: float,
                  box_time_mm: float) -> Target:
    """The CSV or analytic target on the tau grid up to ``t_mm``; analytic fractions of the domain box."""
    if analytic is None:
        return target_from_curve(*curve, t_mm, config.samples, source=config.target)
    q, final, duration = analytic
    if not 0 < final <= 1 or not 0 < duration <= 1:
        raise DesignError(f"analytic final and duration are fractions in (0, 1], got {final}, {duration}")
    if duration * box_time_mm > t_mm:
        raise DesignError(f"the release lasts {duration * box_time_mm:.4g} mm but the design domain dissolves by "
                          f"T = {t_mm:.4g} mm; raise the extrusion height to at least {2 * duration * box_time_mm:.4g} mm")
    return constant_acceleration(t_mm, final * box_volume_mm3, duration * box_time_mm, q, config.samples)


def extrusion_height_mm(target: Target, dx_mm: float) -> float:
    """Default extrusion height for a target without a source shape, mm.

    As tall as a cube of the target's volume (a compact dose form), but at least twice the release's
    duration plus a voxel on each face: the top and bottom faces dissolve inwards at unit speed, so a
    shorter extrusion would be gone before the target's release ends.
    """
    end = curve_end_mm(target.tau_mm, target.released_mm3)
    return max(target.final_mm3 ** (1.0 / 3.0), 2.0 * end + 2.0 * dx_mm)


def start_regions(space: DesignSpace, target: Target, half_extent_mm: np.ndarray | None,
                  radius_mm: float) -> tuple[np.ndarray | None, ...]:
    """Where an extruded design may start with material (`DesignObjective.uniform_start`), the default first.

    A single run starts in the first; the starts of a multi-start take them in turn
    (`design.inverse.multistart.perturbed_start`). None stands for the whole domain.

    The outline is the source's footprint (its bounding box plus a voxel), or for a target without a
    source a centred square. Spreading the start over the whole domain footprint, as for the other
    spaces, leaves an extruded design far from the compact part and lets it split into one piece per
    quadrant (docs/design.md#extruded-start).

    When the extrusion is taller than twice the target's release end D, the start leaves out the
    outline's core deeper than 2 D from its edge. A point of a prism dissolves at min(in-plane distance
    to the nearest edge, distance to the top or bottom face), so the part's material must lie within D
    of an in-plane edge for its release to end by D; the band that remains has that width between the
    outline and the hole, and a start that holds the core solid gives the design a core that the
    projection then keeps (a ring's central hole never opens). The hole is cut only
    as far as the band that remains holds the target's volume at density `START_FILL`, and not at all
    when its half-width would be below the smoothing radius (the filter would keep it a grey pin-hole
    that the printed solid opens). A target without a source starts in the square that holds its
    volume at `START_FILL` throughout, so it has no room for a hole (a square ring start with the
    core's connectivity penalty closes up). When a solid square of its volume would release its core
    after D, two more outlines hold its volume within about D of an edge: a cross of arms about 2 D wide
    (`cross_region`) and a ring of that width (`ring_region`); which of the three the optimisation makes the
    best design of depends on the target, so its multi-start tries each.

    Returns
    -------
    tuple of (ndarray of bool, variable shape, or None)
    """
    if not space.extruded:
        return (None,)
    dx = space.dx_mm
    height_mm = space.grid_shape[BUILD_AXIS] * dx
    end_mm = curve_end_mm(target.tau_mm, target.released_mm3)
    need_cells = target.final_mm3 / (START_FILL * height_mm * dx * dx * space.multiplicity)
    late = end_mm < 0.5 * height_mm - 0.5 * dx  # the faces alone do not dissolve the core in time
    band_mm = 2.0 * end_mm + 0.5 * dx  # a band this wide releases by D from its two edges (half a voxel's ramp)
    alternatives: tuple[np.ndarray | None, ...] = ()
    if half_extent_mm is None:
        area = target.final_mm3 / (height_mm * START_FILL)
        if late and 0.5 * np.sqrt(target.final_mm3 / height_mm) > end_mm:  # a solid square's core releases after D
            outlines = (cross_region(space, area, end_mm), ring_region(space, area, band_mm, radius_mm))
            alternatives = tuple(outline for outline in outlines if outline is not None)
        half = np.full(2, 0.5 * np.sqrt(area))
    else:
        half = np.array([half_extent_mm[ax] for ax in range(3) if ax != BUILD_AXIS]) + dx
    half = np.minimum(half, np.asarray(space.var_shape, float) * dx)  # within the domain
    centres = [(np.arange(n) + 0.5) * dx for n in space.var_shape]
    depth = np.minimum.outer(half[0] - centres[0], half[1] - centres[1])  # to the outline's edge, mm
    region = depth > 0
    if late:
        inside = np.sort(depth[region])
        width = band_mm
        if np.count_nonzero(inside <= width) < need_cells:
            width = inside[min(int(np.ceil(need_cells)), inside.size - 1)]
        if inside[-1] - width >= radius_mm:
            region &= depth <= width
    return (region if region.any() and not region.all() else None,) + alternatives


def cross_region(space: DesignSpace, area_mm2: float, end_mm: float) -> np.ndarray | None:
    """A centred cross of two arms about 2 ``end_mm`` wide whose footprint is ``area_mm2`` (mm^2, all quadrants).

    Its material lies within ``end_mm`` of an edge (at the crossing within sqrt(2) ``end_mm`` of the corners), so
    it releases about when the target ends; arms longer than the domain allows are widened instead. The arms
    lie on the mirror planes, so each quadrant holds one connected L. Widths and lengths are whole cells.
    Returns the region in the variable's quadrant, or None (no cross fits the domain).
    """
    dx = space.dx_mm
    longest = min(space.var_shape) - 1  # cells from the symmetry centre, a cell short of the domain's edge
    width = max(1, int(round(end_mm / dx)))  # half-width, cells
    length = int(round((area_mm2 / dx ** 2 + 4.0 * width ** 2) / (8.0 * width)))  # 8 l w - 4 w^2 = area
    if length > longest:
        disc = 64.0 * longest ** 2 - 16.0 * area_mm2 / dx ** 2
        if disc < 0.0:
            return None
        length, width = longest, max(width, int(round((8.0 * longest - np.sqrt(disc)) / 8.0)))
    cells = [np.arange(n) for n in space.var_shape]
    region = np.logical_and.outer(cells[0] < length, cells[1] < width) | \
        np.logical_and.outer(cells[0] < width, cells[1] < length)
    return region if region.any() and not region.all() else None


def ring_region(space: DesignSpace, area_mm2: float, width_mm: float, radius_mm: float) -> np.ndarray | None:
    """A ring ``width_mm`` wide around the symmetry axis whose footprint is ``area_mm2`` (mm^2, all quadrants).

    A wall of even thickness releases at a rate that changes little (its inner face grows as its outer face
    shrinks) and its material ends at once, when the target ends for a width of twice its end (the band of
    `start_regions`): the outline of a curve that rises steadily and stops, a flat print's. Returns the region
    in the variable's quadrant, or None when the hole would be narrower than the smoothing radius ``radius_mm``
    (the filter would keep it a grey pin-hole) or the ring does not fit the domain with a cell to spare.
    """
    dx = space.dx_mm
    mean_radius = area_mm2 / (2.0 * np.pi * width_mm)
    inner, outer = mean_radius - 0.5 * width_mm, mean_radius + 0.5 * width_mm
    if inner < radius_mm or outer > (min(space.var_shape) - 1) * dx:
        return None
    centres = [(np.arange(n) + 0.5) * dx for n in space.var_shape]
    radius = np.hypot.outer(centres[0], centres[1])
    region = (radius >= inner) & (radius <= outer)
    return region if region.any() else None


def _radius_vox(config: DesignConfig, dx_mm: float) -> float:
    """The smoothing radius in voxels of edge ``dx_mm``: as given, or from mm (at least 1 voxel)."""
    if config.radius_vox is not None:
        return float(config.radius_vox)
    radius_mm = DEFAULT_RADIUS_MM if config.radius_mm is None else config.radius_mm
    radius = max(1.0, radius_mm / dx_mm)
    if radius > 64.0:
        raise DesignError(f"smoothing radius {radius_mm} mm is {radius:.1f} voxels of {dx_mm:.4g} mm; the filter "
                          f"takes at most 64 (lower the resolution or the radius)")
    return radius


def prepare(config: DesignConfig, *, mesh: trimesh.Trimesh | None = None,
            curve: tuple[np.ndarray, np.ndarray] | None = None) -> Problem:
    """Build the design space, the target on its tau grid, and the feasibility report.

    Parameters
    ----------
    config : DesignConfig
    mesh : trimesh.Trimesh, optional
        The source mesh of a mesh-file target (`target_file` "mesh"), mm, as loaded.
    curve : (tau_mm, released_mm3) of (N,) ndarrays of float, optional
        The columns of a CSV target (`target_file` "csv"), as written.
        `design.files.targets_io.load_problem` reads both from the target's file and calls this.

    Raises
    ------
    DesignError
        On a target spec that names nothing known, a file target without its contents, or a problem
        the settings cannot build.
    """
    mesh = _source_mesh(config.target, mesh)
    analytic = None if mesh is not None else _parse_analytic(config.target)
    if mesh is None and analytic is None and not config.target.lower().endswith(".csv"):
        raise DesignError(f"target {config.target!r} is neither a sample shape ({', '.join(SAMPLE_SHAPES)}), "
                          f"a mesh file ({', '.join(MESH_SUFFIXES)}), a .csv curve, nor zero-order/accel:q=..")
    if mesh is None and analytic is None and curve is None:
        raise DesignError(f"target {config.target!r} is a CSV file: read it with design.files.targets_io.load_problem")
    lo = hi = None
    if mesh is not None:
        lo, hi = np.asarray(mesh.bounds[0], float), np.asarray(mesh.bounds[1], float)
    if config.domain_mm is not None:
        size = np.asarray(config.domain_mm, float)
    elif mesh is not None:
        size = (hi - lo) + 2.0 * config.margin * float(np.max(hi - lo))
        if config.space == "ico":  # the part stands on the build plate: no margin below it (section 3.6)
            size[BUILD_AXIS] -= config.margin * float(np.max(hi - lo))
        if config.space == "nfc":
            size = np.full(3, size.max())
    elif analytic is None:  # a CSV curve: a cube whose horizon T holds the whole release
        tau, c = curve
        size = np.full(3, max(DEFAULT_DOMAIN_MM, CSV_HORIZON_MARGIN * 2.0 * curve_end_mm(tau, c)))
    else:
        size = np.full(3, DEFAULT_DOMAIN_MM)
    dx = float(size.max()) / config.resolution
    full = [_even_ceil(s / dx - 1e-9) for s in size]
    # analytic fractions refer to the whole domain box, whatever the extrusion height
    box_volume = float(np.prod(full)) * dx ** 3
    box_time = total_time(tuple(n // 2 for n in full), dx, (True, True, True), config.anisotropy)
    height_vox = None
    if config.space == "extruded":
        height = config.height_mm or (config.height_fraction * float(size.max()) if config.height_fraction else None)
        height = height or (float(hi[BUILD_AXIS] - lo[BUILD_AXIS]) if mesh is not None else extrusion_height_mm(
            _curve_target(config, analytic, curve, box_time, box_volume, box_time), dx))
        if height is not None:
            height_vox = max(1, int(round(height / dx)))
            full[BUILD_AXIS] = max(full[BUILD_AXIS], height_vox)
    ico = IcoConfig(config.layers, config.ico_coarsen, config.stiffness_law)
    space: DesignSpace = build_space(config.space, SpaceRequest(tuple(full), dx, height_vox, ico))
    sim_full = list(space.grid_shape)
    for ax, mir in enumerate(space.mirror):
        sim_full[ax] *= 2 if mir else 1
    sim_full = tuple(sim_full)
    centre = 0.5 * (lo + hi) if mesh is not None else np.zeros(3)
    origin = centre - 0.5 * dx * np.asarray(sim_full, float)
    if config.space == "ico" and mesh is not None:
        origin[BUILD_AXIS] = lo[BUILD_AXIS]  # the source's base on the plate, z = 0 of the grid
    t_total = total_time(space.grid_shape, dx, space.mirror, config.anisotropy)
    domain_volume = float(np.prod(sim_full)) * dx ** 3
    source_solid = None
    target_error = None
    if mesh is not None:
        # the source's physical release (exact surface distances), not its release on the design grid
        grid_tau = tau_grid(t_total, config.samples)
        reference = reference_release(mesh, grid_tau, cells=design_lattice(config.resolution))
        target = Target(grid_tau, reference.released_mm3, f"mesh:{config.target}")
        target_error = reference.error_mm3
        source_solid = voxelize(mesh, dx, origin_mm=origin, shape=sim_full) > 0.5
    else:
        target = _curve_target(config, analytic, curve, t_total, box_volume, box_time)
    ext = np.asarray(sim_full, float) * dx
    area = 2.0 * float(ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2])
    feasibility = check_feasibility(target, domain_volume, dx_mm=dx, domain_area_mm2=area)
    log.info("design grid %s (reduced %s), dx = %.4g mm, T = %.4g mm; %s", sim_full, space.grid_shape, dx,
             t_total, feasibility.text())
    half_mm = 0.5 * (hi - lo) if mesh is not None else None
    radius_vox = _radius_vox(config, dx)
    warnings = (source_warnings(source_solid, config.allow_pieces)
                + rate_resolution_warnings(target, dx, config.w_rate, config.resolution))
    for warning in warnings:
        log.warning("%s", warning)
    return Problem(space, target, feasibility, dx, origin, sim_full, source_solid, radius_vox,
                   start_regions(space, target, half_mm, radius_vox * dx), warnings, mesh, target_error)
