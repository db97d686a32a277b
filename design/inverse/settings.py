"""The design settings, each declared once: its `DesignConfig` field, unit, allowed values, default, option and help.

From these declarations are made the ``sfr design`` options and their help texts
(`labapp.cli.commands.design`), the design launcher's fields (`labapp.gui.design_launcher`) and the range checks of
`design.inverse.config.check_config`. A default that depends on other settings (the design space, the target, the
resolution) is None here and resolved by `design.inverse.config.resolved_defaults` from the constants below.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from design.errors import DesignError
from design.fabrication.connectivity import TAIL_SLOPE
from design.fabrication.elasticity import LAWS
from design.fabrication.ico import DEFAULT_COARSEN, DEFAULT_LAYERS, MAX_COARSEN, MAX_LAYERS
from design.geometry.voxelize import DEFAULT_RESOLUTION
from design.inverse.filters import MAX_RADIUS_VOX
from design.inverse.lbfgs import LINE_SEARCHES
from design.inverse.spaces import SPACE_CHOICES
from design.inverse.targets import TAU_SAMPLES

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
MULTISTART_STARTS = 4
MULTISTART_MIN_RESOLUTION = 128
MULTISTART_SPACES = ("nfc", "extruded")
"""Default multi-start (`DesignConfig.starts`): 4 seeded starts at half the resolution, then the best
refined, for nfc and extruded designs of a source shape at resolution 128 or finer; ICO designs and curve
targets in nfc keep one start. Why: docs/design.md#multi-start."""
COARSE_EVALS_SHARE = 0.5
"""Evaluations of each coarse start of a multi-start, as a share of `DesignConfig.max_iter` (at least 1): the coarse
starts only rank the outlines by J and give the refinement its start; past half the budget their J moves little
(docs/evidence/design.md#a-default-design-at-128-in-two-minutes)."""
REFINE_EVALS_SHARE = {"extruded": 0.5}
"""Evaluations of a multi-start's refinement before its correction rounds, as a share of `DesignConfig.max_iter`
(at least 1), its beta continuation over them, per design space (`DEFAULT_REFINE_EVALS_SHARE` for the others): from
the best coarse design each beta stage settles within a few tens of evaluations; the rounds' evaluations follow as
for a single run. An extruded evaluation at 128 costs a third of an nfc one (its density is 2D), and its longer
refinement printed as well or better on six of seven sources at 128, within a minute each
(docs/evidence/design.md#the-extruded-refinement)."""
DEFAULT_REFINE_EVALS_SHARE = 0.2
"""`REFINE_EVALS_SHARE` of the spaces it does not name (docs/evidence/design.md#a-default-design-at-128-in-two-minutes)."""
CURVE_EXTRUDED_STARTS = 3
"""Default starts of an extruded design of a curve target (`DesignConfig.starts`): its three start outlines, a
square, a cross and a ring (`design.inverse.starts.start_regions`; noisy squares in place of those that do not fit),
each a whole run below `MULTISTART_MIN_RESOLUTION`, the one whose print fits best kept
(docs/design.md#multi-start)."""
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
CORRECTION_SPACES = ("nfc", "extruded", "ico")
"""The design spaces whose runs correct the print by default (`DesignConfig.physical_correction` None): all
(docs/design.md#physical-correction)."""
CORRECTION_ROUNDS = 2
"""Default defect-correction rounds (`DesignConfig.correction_rounds`)."""
CORRECTION_EVALS_SHARE = 0.1
"""Default evaluations of each correction round, as a share of `DesignConfig.max_iter` (at least 1), for the spaces
`SPACE_CORRECTION_EVALS_SHARE` does not name."""
SPACE_CORRECTION_EVALS_SHARE = {"ico": 0.2}
"""`CORRECTION_EVALS_SHARE` per design space. An ICO design's J_fab and J_binary hold it where the optimiser moves
slowly: a round of 10 % leaves J_fit far from its new aim (the cone on its tip at resolution 48: prints 3.96 %,
2.91 %, 2.02 %), one of 20 % reaches it (3.96 % to 0.98 %), and the first optimisation, which has stopped improving
by then, loses nothing (docs/design.md#physical-correction)."""
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
BETA_STAGES = 4
"""Stages of the beta continuation (`DesignConfig.beta_final`, `design.inverse.optimize`)."""
MAX_BETA = 64.0
"""The steepest projection a run takes, at its start or its end (`DesignConfig.beta`, ``beta_final``)."""
MESH_FORMATS = ("3mf", "obj")
"""Mesh formats a run exports besides STL (`DesignConfig.formats`)."""


@dataclass(frozen=True)
class DesignSetting:
    """One design setting: its `DesignConfig` field, allowed values, default, command-line option and help.

    Parameters
    ----------
    name : str
        Field of `DesignConfig` and key of ``config.json``.
    label : str
        What it is, for GUI labels and messages.
    unit : str
        Unit of the value ('' for a count, a weight or a name).
    default : object
        `DesignConfig`'s default; None for a setting resolved from others (`design.inverse.config.resolved_defaults`)
        or not given.
    low, high : float, optional
        Allowed range of a number (of each of its ``count`` numbers); None: unbounded on that side.
    low_open, high_open : bool
        The bound itself is excluded.
    integer, even : bool
        Whole numbers only; even ones only.
    optional : bool
        None is allowed.
    choices : tuple
        The only allowed values (of each, for ``many``).
    kind : str
        "number", "text" or "switch" (True or False).
    count : int, optional
        A tuple of this many numbers (``--domain-mm X Y Z``).
    many : bool
        A tuple of any number of ``choices``.
    flag : str, optional
        ``sfr design`` option; None: set through the API, a sweep or a preset only.
    text : str
        The option's help text.
    metavar : str or tuple of str, optional
        The option's placeholder (default: the flag's name in capitals).
    choices_checked : bool
        The command line refuses a text outside ``choices`` (else the configuration does).
    message : str
        `check_config`'s error for a value outside the range, formatted with the configuration's fields.
    decimals : int
        Decimals shown in the GUI.
    """

    name: str
    label: str
    unit: str = ""
    default: Any = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    integer: bool = False
    even: bool = False
    optional: bool = False
    choices: tuple = ()
    kind: str = "number"
    count: int | None = None
    many: bool = False
    flag: str | None = None
    text: str = ""
    metavar: str | tuple[str, ...] | None = None
    choices_checked: bool = False
    message: str = ""
    decimals: int = 0

    @property
    def display_unit(self) -> str:
        """The unit the command line and the GUI show."""
        return self.unit

    def allows_item(self, value: Any) -> bool:
        """Whether one number or name is allowed (one item of a tuple setting); the command line's check."""
        if self.choices:
            return value in self.choices
        if self.kind != "number":
            return True
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            return False
        if (self.integer and value != int(value)) or (self.even and value % 2):
            return False
        if self.low is not None and not (value > self.low if self.low_open else value >= self.low):
            return False
        return self.high is None or (value < self.high if self.high_open else value <= self.high)

    def allows(self, value: Any) -> bool:
        """Whether ``value`` is allowed: in the range or among the choices (each item of a tuple setting)."""
        if value is None:
            return self.optional
        if self.count is not None or self.many:
            items = tuple(value) if isinstance(value, (tuple, list)) else None
            return items is not None and (self.many or len(items) == self.count) and all(map(self.allows_item, items))
        return self.allows_item(value)

    def range_text(self, shown: bool = False) -> str:
        """The allowed values in words: ``>= 8 voxels (even)``, ``in (0, 64]``, ``one of nfc, extruded, ico``.

        ``shown`` is accepted for the bench's form fields (`labapp.gui.fields.SettingBox`): the command line and
        the GUI show a design setting in its stored unit.
        """
        if self.choices:
            return "one of " + ", ".join(map(str, self.choices))
        tail = (f" {self.unit}" if self.unit else "") + (" (even)" if self.even else "")
        if self.low is not None and self.high is not None:
            return f"in {'(' if self.low_open else '['}{self.low:g}, {self.high:g}{')' if self.high_open else ']'}{tail}"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {self.low:g}{tail}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {self.high:g}{tail}"
        return "finite"

    def shown(self, value: Any) -> Any:
        """A value as the GUI shows it (design settings are shown in their stored unit)."""
        return value

    def stored(self, value: Any) -> Any:
        """A value from the GUI in the stored type (a whole number for an integer setting)."""
        return int(value) if self.integer else value

    def help(self) -> str:
        """The help text of the option (a GUI field's tooltip)."""
        return self.text

    def check(self, config: Any) -> None:
        """Raise DesignError with ``message`` unless the configuration's value of this setting is allowed."""
        if not self.allows(getattr(config, self.name)):
            raise DesignError(self.message.format_map(vars(config)))


def _choices(values: tuple[str, ...]) -> str:
    return "{" + ",".join(values) + "}"


_EVALS = "need max_iter >= 1, checkpoint_every >= 1, lbfgs_memory in [1, 100]; got {max_iter}, {checkpoint_every}, " \
         "{lbfgs_memory}"
_GRID = "need margin in [0, 2], warn_channel_mm > 0, samples >= 3; got {margin}, {warn_channel_mm}, {samples}"
_RATE_SPAN, _RATE_WINDOW, _MAX_ITER, _BOUNDS = (0.05, 0.95), 1.0, 500, ("cosine", "box")
_RATE = "w_rate must be >= 0 and rate_window_vox in (0, 64]; got {w_rate}, {rate_window_vox}"
_ROUNDS = "need correction_rounds in [1, 10] and correction_evals >= 1; got {correction_rounds}, {correction_evals}"

# -- the design settings ``sfr design`` offers, in the order of its help ---------------------------------------------
SPACE = DesignSetting(
    "space", "space", default=SPACE_CHOICES[0], kind="text", choices=SPACE_CHOICES, flag="--space", choices_checked=True,
    text="design space: nfc (free 3D, the default), extruded (2D field over a height), ico (free 3D, printable without "
         "supports along +z: incremental compliance, section 3.6)",
    message=f"space must be one of {SPACE_CHOICES}, got {{space!r}}")
PRESET = DesignSetting(
    "preset", "paper preset", kind="text", optional=True, flag="--preset", metavar="paper:NAME",
    text="hyperparameters of the paper's Tables 1-2 (e.g. paper:pill, paper:design-4) for the options not given")
W_FAB = DesignSetting(
    "w_fab", "ICO weight w_f", default=None, low=0.0, flag="--w-fab",
    text=f"weight w_f of the ICO term (ico; default {SPACE_DEFAULTS['ico']['w_fab']:g}; J_fab is 1 at the start design)",
    message="w_fab must be >= 0, and only the ico space has a fabrication term; got {w_fab} for space {space!r}")
LAYERS = DesignSetting(
    "layers", "ICO partial designs L", default=DEFAULT_LAYERS, low=1, high=MAX_LAYERS, integer=True, flag="--layers",
    text=f"ICO partial designs L along +z (default {DEFAULT_LAYERS})")
ICO_COARSEN = DesignSetting(
    "ico_coarsen", "design voxels per elasticity element edge", "voxels", DEFAULT_COARSEN, low=1, high=MAX_COARSEN,
    integer=True, flag="--ico-coarsen", metavar="VOX",
    text=f"design voxels per elasticity element edge of the ICO term (default {DEFAULT_COARSEN})")
STIFFNESS_LAW = DesignSetting(
    "stiffness_law", "ICO stiffness interpolation", default=LAWS[0], kind="text", choices=LAWS,
    flag="--stiffness-law", choices_checked=True,
    text="ICO stiffness interpolation: simp (p = 3, default) or ramp (q = 3)")
RESOLUTION = DesignSetting(
    "resolution", "resolution", "voxels", DEFAULT_RESOLUTION, low=8, integer=True, even=True, flag="--resolution",
    text=f"voxels along the domain's longest side (even; default {DEFAULT_RESOLUTION})",
    message="resolution must be an even number >= 8 voxels, got {resolution}")
DOMAIN = DesignSetting(
    "domain_mm", "design domain size", "mm", low=0.0, low_open=True, optional=True, count=3, flag="--domain-mm",
    metavar=("X", "Y", "Z"), text="design domain size, mm (default: source bounding box plus margin, cubic for nfc)",
    message="domain must be three positive sizes in mm, got {domain_mm}")
W_BINARY = DesignSetting(
    "w_binary", "J_binary weight", low=0.0, optional=True, flag="--w-binary",
    text="weight of J_binary (default per space, Tables 1-2)", message="w_binary must be >= 0, got {w_binary}")
RADIUS = DesignSetting(
    "radius_vox", "smoothing radius", "voxels", low=1.0, high=MAX_RADIUS_VOX, optional=True, flag="--radius",
    text="smoothing radius, voxels (default: --radius-mm)",
    message=f"smoothing radius must be in [1, {MAX_RADIUS_VOX:g}] voxels, got {{radius_vox}}")
RADIUS_MM = DesignSetting(
    "radius_mm", "smoothing radius", "mm", low=0.0, low_open=True, optional=True, flag="--radius-mm", metavar="MM",
    text=f"smoothing radius, mm: the minimum feature size at any resolution (default {DEFAULT_RADIUS_MM:g})",
    message="smoothing radius must be > 0 mm, got {radius_mm}")
ALLOW_PIECES = DesignSetting(
    "allow_pieces", "allow pieces", default=False, kind="switch", flag="--allow-pieces",
    text="drop the connectivity penalty: the design may fall apart into pieces")
W_CONNECT_SETTING = DesignSetting(
    "w_connect", "J_conn weight", low=0.0, flag="--w-connect",
    text=f"weight of the connectivity penalty J_conn (default {W_CONNECT:g}; "
         f"{ANALYTIC_DEFAULTS['extruded']['w_connect']:g} for analytic targets in extruded)",
    message="w_connect must be >= 0, got {w_connect}")
W_CHANNEL_SETTING = DesignSetting(
    "w_channel", "J_chan weight", low=0.0, optional=True, flag="--w-channel",
    text=f"weight of the channel-width term J_chan, which keeps open channels at least the calibration's swelling "
         f"width (--simcal with one; default {W_CHANNEL:g}, 0 = off)",
    message="w_channel must be a finite number >= 0, got {w_channel!r}")
STARTS = DesignSetting(
    "starts", "seeded starts", low=1, high=64, integer=True, flag="--starts",
    text=f"seeded starts: from resolution {MULTISTART_MIN_RESOLUTION} on at half the resolution, the best then refined "
         f"at full resolution; below it each a whole run, the best print kept (default {MULTISTART_STARTS} for nfc "
         f"and extruded designs of a source shape at resolution {MULTISTART_MIN_RESOLUTION} or finer, "
         f"{CURVE_EXTRUDED_STARTS} for extruded designs of a curve target, one from each start outline: square, "
         f"cross, ring; else 1: a single run)",
    message="starts must be in [1, 64], got {starts}")
BETA = DesignSetting(
    "beta", "projection steepness", low=0.0, high=MAX_BETA, low_open=True, optional=True, flag="--beta",
    text=f"projection steepness (default {SPACE_DEFAULTS['nfc']['beta']:g})",
    message=f"beta must be in (0, {MAX_BETA:g}], got {{beta}}")
BETA_FINAL = DesignSetting(
    "beta_final", "final projection steepness", low=0.0, low_open=True, optional=True, flag="--beta-final",
    text=f"beta continuation: raise beta to this over the run in {BETA_STAGES} stages (default "
         f"{SPACE_DEFAULTS['nfc']['beta_final']:g} for nfc and extruded, {ANALYTIC_DEFAULTS['nfc']['beta_final']:g} "
         f"for analytic targets there, fixed for ico; equal to --beta: fixed)",
    message=f"beta_final must be in [beta, {MAX_BETA:g}] = [{{beta}}, {MAX_BETA:g}], got {{beta_final}}")
RATE_WINDOW = DesignSetting(
    "rate_window_vox", "rate-fit span", "voxels", _RATE_WINDOW, low=0.0, high=64.0, low_open=True, flag="--rate-window",
    metavar="VOX", text=f"finite-difference span of the rate-fit term's rates, voxels (default {_RATE_WINDOW:g})",
    message=_RATE)
W_RATE = DesignSetting(
    "w_rate", "J_rate weight", low=0.0, flag="--w-rate",
    text=f"weight of the rate-fit term J_rate (default {ANALYTIC_W_RATE:g} for analytic targets, else 0)",
    message=_RATE)
RATE_SPAN = DesignSetting(
    "rate_span", "rate-fit span of the release", default=_RATE_SPAN, low=0.0, high=1.0, count=2, flag="--rate-span",
    metavar=("LO", "HI"),
    text="J_rate compares rates between the times the target reaches these fractions of its release (default "
         f"{_RATE_SPAN[0]:g} {_RATE_SPAN[1]:g}; 0 1 = whole curve)",
    message="rate_span must be two fractions 0 <= lo < hi <= 1, got {rate_span}")
ROBUST_ETA = DesignSetting(
    "robust_eta", "robust threshold offset", low=0.0, high=0.4, flag="--robust-eta", metavar="D",
    text=f"robust formulation: fit the designs projected at 1/2 - D, 1/2, 1/2 + D (0 = off; 3 simulations per "
         f"evaluation; default {ANALYTIC_DEFAULTS['nfc']['robust_eta']:g} for analytic targets in nfc and extruded, "
         f"else 0)",
    message="robust_eta must be in [0, 0.4], got {robust_eta}")
HEIGHT = DesignSetting(
    "height_mm", "extrusion height", "mm", low=0.0, low_open=True, optional=True, flag="--height", metavar="MM",
    text="extrusion height, mm (default: the source's height, else the domain's)",
    message="extrusion height must be > 0 mm, got {height_mm}")
MAX_ITER = DesignSetting(
    "max_iter", "max iterations", default=_MAX_ITER, low=1, integer=True, flag="--max-iter",
    text=f"maximum objective evaluations (default {_MAX_ITER})", message=_EVALS)
PHYSICAL_CORRECTION = DesignSetting(
    "physical_correction", "physical correction", kind="text", choices=PHYSICAL_CORRECTIONS,
    flag="--physical-correction", metavar=_choices(PHYSICAL_CORRECTIONS),
    text="how the printed solid's true release is made to meet the target: defect (default: rounds that re-aim the "
         "design grid by the bias the reference evaluator finds in the print, within --max-iter) or none (the design "
         "grid's release alone)",
    message=f"physical_correction must be one of {PHYSICAL_CORRECTIONS}, got {{physical_correction!r}}")
CORRECTION_ROUNDS_SETTING = DesignSetting(
    "correction_rounds", "defect-correction rounds", default=CORRECTION_ROUNDS, low=1, high=10, integer=True,
    flag="--correction-rounds", metavar="N",
    text=f"defect-correction rounds (default {CORRECTION_ROUNDS}, each {100 * CORRECTION_EVALS_SHARE:g}%% of "
         f"--max-iter; {100 * SPACE_CORRECTION_EVALS_SHARE['ico']:g}%% for ico)",
    message=_ROUNDS)
BOUNDS = DesignSetting(
    "bounds", "variable bounds", default=_BOUNDS[0], kind="text", choices=_BOUNDS, flag="--bounds",
    choices_checked=True, text=f"how L-BFGS keeps rho_hat in [0, 1] (default {_BOUNDS[0]})",
    message="bounds must be 'cosine' or 'box', got {bounds!r}")
OPTIMIZER = DesignSetting(
    "optimizer", "optimiser", default=OPTIMIZERS[0], kind="text", choices=OPTIMIZERS, flag="--optimizer",
    text="lbfgs (default: lean L-BFGS, exact resume) or nlopt's LD_LBFGS, LD_MMA, LD_CCSAQ (box bounds need one of "
         "these); checked by the design configuration",
    message=f"optimizer must be one of {OPTIMIZERS}, got {{optimizer!r}}")
LINE_SEARCH = DesignSetting(
    "line_search", "line search", default=LINE_SEARCHES[0], kind="text", choices=LINE_SEARCHES, flag="--line-search",
    text="the lbfgs optimiser's line search: luksan (default; the rule of nlopt's LD_LBFGS) or strong-wolfe; checked "
         "by the design configuration",
    message=f"line_search must be one of {LINE_SEARCHES}, got {{line_search!r}}")
WARN_CHANNEL = DesignSetting(
    "warn_channel_mm", "narrow-channel warning", "mm", 1.0, low=0.0, low_open=True, flag="--warn-channel-mm",
    text="warn below this channel width, mm", message=_GRID)
FORMATS = DesignSetting(
    "formats", "extra mesh formats", default=(), kind="text", choices=MESH_FORMATS, many=True, flag="--formats",
    choices_checked=True, text="extra mesh formats")
ALLOW_INFEASIBLE = DesignSetting(
    "allow_infeasible", "optimise even if the feasibility check fails", default=False, kind="switch",
    flag="--allow-infeasible", text="optimise even if the target fails checks")

# -- settings without an option: the API's, a sweep's, a preset's or print physics' --------------------------------
HEIGHT_FRACTION = DesignSetting(
    "height_fraction", "extrusion height per domain side", low=0.0, high=1.0, low_open=True, optional=True,
    message="height_fraction must be in (0, 1], got {height_fraction}")
CONNECT_PLANES = DesignSetting("connect_planes", "J_conn plane term", default=True, kind="switch")
CONNECT_TAIL = DesignSetting("connect_tail", "J_conn tail slope", default=TAIL_SLOPE, low=0.0,
                             message="connect_tail must be >= 0, got {connect_tail}")
FTOL = DesignSetting("ftol_rel", "relative tolerance on J", default=0.0)
XTOL = DesignSetting("xtol_rel", "relative tolerance on the variables", default=0.0)
LBFGS_MEMORY = DesignSetting("lbfgs_memory", "L-BFGS correction pairs", default=10, low=1, high=100, integer=True,
                             message=_EVALS)
CHECKPOINT_EVERY = DesignSetting("checkpoint_every", "evaluations between checkpoints", default=10, low=1,
                                 integer=True, message=_EVALS)
MARGIN = DesignSetting("margin", "empty space around a source", default=0.25, low=0.0, high=2.0, message=_GRID)
SAMPLES = DesignSetting("samples", "tau grid points", default=TAU_SAMPLES, low=3, integer=True, message=_GRID)
CORRECTION_EVALS = DesignSetting("correction_evals", "evaluations per correction round", low=1, integer=True,
                                 message=_ROUNDS)
ANISOTROPY = DesignSetting("anisotropy", "erosion speed along z over in-plane", default=1.0, low=0.1, high=10.0,
                           message="anisotropy must be in [0.1, 10], got {anisotropy}")
PRINT_OFFSET = DesignSetting("print_offset_mm", "print offset", "mm", 0.0, low=-5.0, high=5.0,
                             message="print_offset_mm must be a finite number within +-5 mm, got {print_offset_mm}")
SWELLING = DesignSetting("swelling_mm", "swelling width", "mm", 0.0, low=0.0, high=10.0,
                         message="swelling_mm must be in [0, 10] mm, got {swelling_mm}")

OPTIONS: tuple[DesignSetting, ...] = (
    SPACE, PRESET, W_FAB, LAYERS, ICO_COARSEN, STIFFNESS_LAW, RESOLUTION, DOMAIN, W_BINARY, RADIUS, RADIUS_MM,
    ALLOW_PIECES, W_CONNECT_SETTING, W_CHANNEL_SETTING, STARTS, BETA, BETA_FINAL, RATE_WINDOW, W_RATE, RATE_SPAN,
    ROBUST_ETA, HEIGHT, MAX_ITER, PHYSICAL_CORRECTION, CORRECTION_ROUNDS_SETTING, BOUNDS, OPTIMIZER, LINE_SEARCH,
    WARN_CHANNEL, FORMATS, ALLOW_INFEASIBLE)
"""The settings ``sfr design`` offers, in the order of its help."""
SETTINGS: dict[str, DesignSetting] = {s.name: s for s in (*OPTIONS, HEIGHT_FRACTION, CONNECT_PLANES, CONNECT_TAIL,
                                                          FTOL, XTOL, LBFGS_MEMORY, CHECKPOINT_EVERY, MARGIN, SAMPLES,
                                                          CORRECTION_EVALS, ANISOTROPY, PRINT_OFFSET, SWELLING)}
"""Every declared design setting by `DesignConfig` field name (all fields but ``target``)."""


def option_flag(name: str) -> str:
    """The ``sfr design`` option of a `DesignConfig` field (``radius_vox`` -> ``--radius``); a field without one
    is named as an option would be (``checkpoint_every`` -> ``--checkpoint-every``)."""
    setting = SETTINGS.get(name)
    return setting.flag if setting is not None and setting.flag else "--" + name.replace("_", "-")
