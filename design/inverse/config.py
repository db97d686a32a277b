"""`DesignConfig`, everything a design run depends on: its defaults resolved from the other settings, then checked.

The settings are declared in `design.inverse.settings`; `resolved_defaults` fills in the ones whose default
depends on others (the design space, the target, a paper preset, the resolution, the print's swelling) and
`check_config` checks each against its declaration and the conditions between them.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from design.errors import DesignError
from design.fabrication.ico import IcoConfig
from design.inverse.presets import preset_values
from design.inverse.settings import (
    ALLOW_INFEASIBLE,
    ALLOW_PIECES,
    ANALYTIC_DEFAULTS,
    ANALYTIC_W_RATE,
    ANISOTROPY,
    BETA,
    BETA_FINAL,
    BOUNDS,
    CHECKPOINT_EVERY,
    CONNECT_PLANES,
    CONNECT_TAIL,
    CORRECTION_EVALS,
    CORRECTION_EVALS_SHARE,
    CORRECTION_ROUNDS_SETTING,
    CORRECTION_SPACES,
    CURVE_EXTRUDED_STARTS,
    DOMAIN,
    FORMATS,
    FTOL,
    HEIGHT,
    HEIGHT_FRACTION,
    ICO_COARSEN,
    LAYERS,
    LBFGS_MEMORY,
    LINE_SEARCH,
    MARGIN,
    MAX_BETA,
    MAX_ITER,
    MESH_FORMATS,
    MULTISTART_MIN_RESOLUTION,
    MULTISTART_SPACES,
    MULTISTART_STARTS,
    OPTIMIZER,
    PHYSICAL_CORRECTION,
    PHYSICAL_CORRECTIONS,
    PRINT_OFFSET,
    RADIUS,
    RADIUS_MM,
    RATE_SPAN,
    RATE_WINDOW,
    RESOLUTION,
    ROBUST_ETA,
    SAMPLES,
    SPACE,
    SPACE_CORRECTION_EVALS_SHARE,
    SPACE_DEFAULTS,
    STARTS,
    STIFFNESS_LAW,
    SWELLING,
    W_BINARY,
    W_CHANNEL,
    W_CHANNEL_SETTING,
    W_CONNECT,
    W_CONNECT_SETTING,
    W_FAB,
    W_RATE,
    WARN_CHANNEL,
    XTOL,
    DesignSetting,
)
from design.inverse.target_spec import is_shape_target, parse_analytic


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
        Voxels along the full domain's longest side (even, >= 8; `DEFAULT_RESOLUTION`).
    domain_mm : tuple of 3 float or None
        Full domain size (x, y, z), mm; None = the source's bounding box plus ``margin`` on every
        side (cubic for nfc), or a `design.inverse.problem.DEFAULT_DOMAIN_MM` cube for targets without a source.
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
        `DEFAULT_RADIUS_MM`. Converted to voxels of the design grid (at least 1, at most `MAX_RADIUS_VOX`) by
        `design.inverse.problem.prepare`.
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
        `BETA_STAGES` equal stages of the run; equal to ``beta``: fixed, as in the
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
        Points of the tau grid (`TAU_SAMPLES` gives dtau = T/1000, section 3.4).
    formats : tuple of str
        Mesh formats to export besides STL ("3mf", "obj").
    physical_correction : str or None
        One of `PHYSICAL_CORRECTIONS`: how the run makes its print's true release meet the target. None =
        "defect" in `CORRECTION_SPACES`, else "none".
    correction_rounds : int
        Defect-correction rounds after the optimisation (`design.inverse.defect`), 1 to 10.
    correction_evals : int or None
        Objective evaluations of each round, part of ``max_iter``; None = the space's `SPACE_CORRECTION_EVALS_SHARE`,
        else `CORRECTION_EVALS_SHARE`, of ``max_iter`` (at least 1).
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
    space: str = SPACE.default
    resolution: int = RESOLUTION.default
    domain_mm: tuple[float, float, float] | None = None
    height_mm: float | None = None
    height_fraction: float | None = None
    preset: str | None = None
    w_binary: float | None = None
    radius_vox: float | None = None
    radius_mm: float | None = None
    allow_pieces: bool = ALLOW_PIECES.default
    w_connect: float | None = None
    connect_planes: bool = CONNECT_PLANES.default
    connect_tail: float = CONNECT_TAIL.default
    starts: int | None = None
    beta: float | None = None
    w_fab: float | None = None
    layers: int = LAYERS.default
    ico_coarsen: int = ICO_COARSEN.default
    stiffness_law: str = STIFFNESS_LAW.default
    beta_final: float | None = None
    rate_window_vox: float = RATE_WINDOW.default
    w_rate: float | None = None
    rate_span: tuple[float, float] = RATE_SPAN.default
    robust_eta: float | None = None
    max_iter: int = MAX_ITER.default
    optimizer: str = OPTIMIZER.default
    ftol_rel: float = FTOL.default
    xtol_rel: float = XTOL.default
    lbfgs_memory: int = LBFGS_MEMORY.default
    line_search: str = LINE_SEARCH.default
    bounds: str = BOUNDS.default
    checkpoint_every: int = CHECKPOINT_EVERY.default
    margin: float = MARGIN.default
    warn_channel_mm: float = WARN_CHANNEL.default
    allow_infeasible: bool = ALLOW_INFEASIBLE.default
    samples: int = SAMPLES.default
    formats: tuple[str, ...] = FORMATS.default
    physical_correction: str | None = None
    correction_rounds: int = CORRECTION_ROUNDS_SETTING.default
    correction_evals: int | None = None
    anisotropy: float = ANISOTROPY.default
    print_offset_mm: float = PRINT_OFFSET.default
    swelling_mm: float = SWELLING.default
    w_channel: float | None = None

    def __post_init__(self) -> None:
        SPACE.check(self)  # the other defaults are the space's
        for name, value in resolved_defaults(self).items():
            object.__setattr__(self, name, value)
        check_config(self)


def resolved_defaults(config: DesignConfig) -> dict[str, Any]:
    """The values of the settings that ``config`` leaves None and whose defaults depend on other settings.

    A paper preset's values come first, then the space's (`SPACE_DEFAULTS`, for analytic targets with
    `ANALYTIC_DEFAULTS` over them), then ``w_fab`` 0 and ``w_connect`` `W_CONNECT`; ``radius_vox`` stays None
    when ``radius_mm`` is given. Then ``w_rate``, ``robust_eta``, ``starts``, ``w_channel`` (only with swelling),
    ``physical_correction`` and ``correction_evals`` as their declarations say.

    Raises
    ------
    DesignError
        For an unknown preset or a malformed analytic target.
    """
    values = dict(vars(config))
    resolved: dict[str, Any] = {}

    def fill(name: str, value: Any) -> None:
        if values[name] is None:
            values[name] = resolved[name] = value

    presets = [preset_values(config.preset, config.space)] if config.preset is not None else []
    is_analytic = parse_analytic(config.target) is not None
    analytic = ANALYTIC_DEFAULTS.get(config.space, {}) if is_analytic else {}
    space_defaults = {**SPACE_DEFAULTS.get(config.space, {}), **analytic}
    space_defaults.pop("robust_eta", None)  # resolved below, once w_rate is known
    for defaults in presets + [space_defaults, {"w_fab": 0.0, "w_connect": W_CONNECT}]:
        for name, value in defaults.items():
            if not (name == "radius_vox" and config.radius_mm is not None):
                fill(name, max(value, values["beta"]) if name == "beta_final" and values[name] is None else value)
    fill("w_rate", ANALYTIC_W_RATE if is_analytic else 0.0)
    if values["robust_eta"] is None:
        fill("robust_eta", analytic.get("robust_eta", 0.0) if values["w_rate"] > 0 else 0.0)
    if values["starts"] is None:
        shape = is_shape_target(config.target)
        multi = config.space in MULTISTART_SPACES and config.resolution >= MULTISTART_MIN_RESOLUTION and shape
        outlines = config.space == "extruded" and not shape
        fill("starts", MULTISTART_STARTS if multi else CURVE_EXTRUDED_STARTS if outlines else 1)
    if values["w_channel"] is None and config.swelling_mm > 0:
        fill("w_channel", W_CHANNEL)
    if values["physical_correction"] is None:
        correct = config.space in CORRECTION_SPACES and not config.swelling_mm > 0
        fill("physical_correction", PHYSICAL_CORRECTIONS[0] if correct else "none")
    if values["correction_evals"] is None:
        share = SPACE_CORRECTION_EVALS_SHARE.get(config.space, CORRECTION_EVALS_SHARE)
        fill("correction_evals", max(1, int(round(share * config.max_iter))))
    return resolved


@dataclass(frozen=True)
class Rule:
    """A condition between design settings; ``message`` is formatted with the configuration's fields, or made
    from the configuration by a function."""

    holds: Callable[[DesignConfig], bool]
    message: str | Callable[[DesignConfig], str]

    def check(self, config: DesignConfig) -> None:
        """Raise DesignError with ``message`` unless the condition holds."""
        if not self.holds(config):
            message = self.message(config) if callable(self.message) else self.message.format_map(vars(config))
            raise DesignError(message)


def _ico_settings_hold(config: DesignConfig) -> bool:
    IcoConfig(config.layers, config.ico_coarsen, config.stiffness_law)  # the ICO term checks its own settings
    return True


def _bad_formats(config: DesignConfig) -> str:
    bad = set(config.formats) - set(MESH_FORMATS)
    return f"extra mesh formats must be among {', '.join(MESH_FORMATS)}; got {sorted(bad)}"


CHECKS: tuple[DesignSetting | Rule, ...] = (
    SPACE,
    W_FAB,
    Rule(lambda c: not (c.w_fab > 0 and c.space != "ico"), W_FAB.message),
    HEIGHT_FRACTION,
    Rule(_ico_settings_hold, ""),
    W_RATE, RATE_WINDOW,
    RATE_SPAN,
    Rule(lambda c: c.rate_span[0] < c.rate_span[1], RATE_SPAN.message),
    ROBUST_ETA,
    Rule(lambda c: not (c.robust_eta > 0 and not c.w_rate > 0),
         "the robust formulation compares release rates: it needs w_rate > 0"),
    RESOLUTION, DOMAIN, HEIGHT, W_BINARY, RADIUS,
    Rule(lambda c: c.radius_vox is None or c.radius_mm is None,
         "give the smoothing radius in voxels ({radius_vox}) or in mm ({radius_mm}), not both"),
    RADIUS_MM, W_CONNECT_SETTING, CONNECT_TAIL, STARTS, BETA,
    Rule(lambda c: c.beta_final is None or c.beta <= c.beta_final <= MAX_BETA, BETA_FINAL.message),
    MAX_ITER, CHECKPOINT_EVERY, LBFGS_MEMORY,
    MARGIN, WARN_CHANNEL, SAMPLES,
    BOUNDS, OPTIMIZER, LINE_SEARCH,
    Rule(lambda c: not (c.optimizer == "lbfgs" and c.bounds != "cosine"),
         "the 'lbfgs' optimiser is unconstrained: it needs bounds='cosine' (box bounds: choose an nlopt optimizer)"),
    ANISOTROPY, PRINT_OFFSET, SWELLING,
    W_CHANNEL_SETTING,
    Rule(lambda c: not (c.w_channel and not c.swelling_mm > 0),
         "w_channel = {w_channel:g} weighs the minimum open channel width, which is swelling_mm: it needs "
         "swelling_mm > 0"),
    Rule(lambda c: not (c.physical_correction == "defect" and c.swelling_mm > 0),
         "physical_correction 'defect' judges the print by the reference evaluator, which does not shut channels "
         "narrower than swelling_mm ({swelling_mm:g} mm); use 'none' with swelling"),
    PHYSICAL_CORRECTION,
    CORRECTION_ROUNDS_SETTING, CORRECTION_EVALS,
    Rule(lambda c: not set(c.formats) - set(MESH_FORMATS), _bad_formats),
)
"""What `check_config` checks, in order: each declared setting's range and the conditions between settings."""


def check_config(config: DesignConfig) -> None:
    """Check every setting of a configuration whose defaults are resolved (`CHECKS`, in order).

    Raises
    ------
    DesignError
        Naming the first setting out of its range or the first condition broken, with the values.
    """
    for check in CHECKS:
        check.check(config)
