"""Fits of the standard dissolution models to a release curve, ranked by AIC.

The models, with F the percent released at time t (Costa and Sousa Lobo 2001; Zhang et al. 2010,
"DDSolver", AAPS J. 12:263, whose parameter names these follow):

=================  ==========================================  ===============================
zero-order         F = k0 t                                    k0 in %/time
first-order        F = 100 (1 - exp(-k1 t))                     k1 in 1/time
Higuchi            F = kH sqrt(t)                              kH in %/time^0.5
Korsmeyer-Peppas   F = kKP t^n, on the points with F <= 60 %   kKP in %/time^n, n
Hixson-Crowell     F = 100 (1 - (1 - kHC t)^3), 100 after 1/kHC   kHC in 1/time
Weibull            F = 100 (1 - exp(-(t / td)^beta))           td in time, beta
Hopfenberg         F = 100 (1 - (1 - kHB t)^n), 100 after 1/kHB   kHB in 1/time, n
Peppas-Sahlin      F = k1 t^m + k2 t^(2m), on F <= 60 %        k1 in %/time^m, k2 in %/time^2m, m
Baker-Lonsdale     3/2 (1 - (1 - F/100)^(2/3)) - F/100 = kBL t  kBL in 1/time
Gompertz           F = 100 exp(-alpha t^(-beta))               alpha in time^beta, beta
=================  ==========================================  ===============================

Hopfenberg's surface-erosion model (Hopfenberg 1976; Katzhendler et al. 1997) is the release of a slab
(n = 1), cylinder (2) or sphere (3) eroding at a constant rate from its surface, kHB = k0 / (C0 a0); the
forward model of this project (paper, eqs. 6-7) generalises it to any shape and density. Peppas-Sahlin
(1989) splits the release into a Fickian (k1) and a relaxational (k2, of either sign) part; Baker-Lonsdale
(1974) is diffusion from a sphere, 100 % when kBL t reaches 1/2; Gompertz as in DDSolver (Zhang et al. 2010).

Each fit is ordinary least squares on the points with t > 0 (time zero fits every model exactly), with
R^2 = 1 - SSR/SST, adjusted R^2 = 1 - (1 - R^2)(n - 1)/(n - p) and AIC = n ln(SSR/n) + 2p. AIC compares
models only on the same points, so Korsmeyer-Peppas and Peppas-Sahlin, fitted on the first 60 %, are ranked
with the others only when that is the whole curve; otherwise they are listed after them, unranked.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from analysis.errors import AnalysisError
from analysis.profile import ReleaseProfile

KP_LIMIT_PCT = 60.0
"""Korsmeyer-Peppas and Peppas-Sahlin are fitted on the points up to this percent released."""
_SSR_FLOOR = 1e-300


def _zero(t, k0):
    return k0 * t


def _first(t, k1):
    return 100.0 * -np.expm1(-k1 * t)


def _higuchi(t, kh):
    return kh * np.sqrt(t)


def _peppas(t, kkp, n):
    return kkp * t ** n


def _hixson(t, khc):
    return 100.0 * (1.0 - np.clip(1.0 - khc * t, 0.0, None) ** 3)


def _weibull(t, td, beta):
    return 100.0 * -np.expm1(-(t / td) ** beta)


def _hopfenberg(t, khb, n):
    return 100.0 * (1.0 - np.clip(1.0 - khb * t, 0.0, None) ** n)


def _peppas_sahlin(t, k1, k2, m):
    tm = t ** m
    return k1 * tm + k2 * tm * tm


BAKER_LONSDALE_END = 0.5
"""kBL t at which Baker-Lonsdale's sphere is fully released."""


def _baker_lonsdale(t, kbl):
    """F solving 3/2 (1 - (1 - f)^(2/3)) - f = kBL t: with u = (1 - f)^(1/3) the left side is
    1/2 - 3/2 u^2 + u^3, decreasing on [0, 1]; u found by bisection to round-off."""
    y = np.clip(kbl * np.asarray(t, dtype=float), 0.0, BAKER_LONSDALE_END)
    lo, hi = np.zeros_like(y), np.ones_like(y)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = 0.5 - 1.5 * mid ** 2 + mid ** 3 > y  # g(mid) > y: the root lies at larger u
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    u = 0.5 * (lo + hi)
    return 100.0 * (1.0 - u ** 3)


def _gompertz(t, alpha, beta):
    with np.errstate(divide="ignore", over="ignore"):
        return 100.0 * np.exp(-alpha * np.asarray(t, dtype=float) ** -beta)


@dataclass(frozen=True)
class _Model:
    name: str
    function: Callable[..., np.ndarray]
    params: tuple[str, ...]
    units: tuple[str, ...]
    early_only: bool = False
    """Fitted on the points up to ``KP_LIMIT_PCT`` (the power laws)."""
    signed: tuple[str, ...] = ()
    """Parameters that may be negative (the others are fitted in log scale)."""


MODELS = (
    _Model("zero-order", _zero, ("k0",), ("%/{t}",)),
    _Model("first-order", _first, ("k1",), ("1/{t}",)),
    _Model("Higuchi", _higuchi, ("kH",), ("%/{t}^0.5",)),
    _Model("Korsmeyer-Peppas", _peppas, ("kKP", "n"), ("%/{t}^n", ""), early_only=True),
    _Model("Hixson-Crowell", _hixson, ("kHC",), ("1/{t}",)),
    _Model("Weibull", _weibull, ("td", "beta"), ("{t}", "")),
    _Model("Hopfenberg", _hopfenberg, ("kHB", "n"), ("1/{t}", "")),
    _Model("Peppas-Sahlin", _peppas_sahlin, ("k1", "k2", "m"), ("%/{t}^m", "%/{t}^2m", ""), early_only=True,
           signed=("k2",)),
    _Model("Baker-Lonsdale", _baker_lonsdale, ("kBL",), ("1/{t}",)),
    _Model("Gompertz", _gompertz, ("alpha", "beta"), ("{t}^beta", "")),
)
"""The fitted models, in the order of the module table."""
MODEL_NAMES = tuple(m.name for m in MODELS)


@dataclass(frozen=True)
class ModelFit:
    """One model fitted to a release curve.

    Attributes
    ----------
    model : str
        One of ``MODEL_NAMES``.
    params : dict of str to float
        Fitted parameters (see the module table), in the curve's time unit.
    units : dict of str to str
        Unit of each parameter.
    r2, r2_adj, aic : float
        Goodness of fit on the fitted points (NaN when the fit failed).
    n_points : int
        Points fitted (t > 0; F <= 60 % for Korsmeyer-Peppas and Peppas-Sahlin).
    rank : int or None
        1 for the lowest AIC among the comparable fits; None when not ranked.
    note : str
        Why a fit is unranked or failed; empty otherwise.
    """

    model: str
    params: dict
    units: dict
    r2: float
    r2_adj: float
    aic: float
    n_points: int
    rank: int | None = None
    note: str = ""

    def percent_at(self, t: np.ndarray) -> np.ndarray:
        """The fitted model's percent released at times ``t`` (the curve's time unit)."""
        model = MODELS[MODEL_NAMES.index(self.model)]
        return model.function(np.asarray(t, dtype=float), *(self.params[p] for p in model.params))

    def describe(self) -> str:
        """E.g. ``Weibull: td = 3120 s, beta = 1.21 (R^2 0.9987, AIC -412.3)``."""
        values = ", ".join(f"{k} = {v:.4g}{' ' + self.units[k] if self.units[k] else ''}"
                           for k, v in self.params.items())
        return f"{self.model}: {values} (R^2 {self.r2:.4f}, AIC {self.aic:.1f})"


def _peppas_sahlin_start(t: np.ndarray, f: np.ndarray) -> list[float]:
    """k1, k2, m by variable projection: for each m the k's are linear least squares; m from a grid, then
    refined (the two power terms make the direct fit converge to swapped local minima)."""
    def solve(m):
        basis = np.column_stack([t ** m, t ** (2 * m)])
        k, *_ = np.linalg.lstsq(basis, f, rcond=None)
        r = basis @ k - f
        return float(r @ r), k

    grid = np.linspace(0.02, 2.0, 100)
    cost = []
    for m in grid:
        c, k = solve(m)
        cost.append(c if k[0] > 0 else np.inf)  # k1 is the Fickian part: positive
    i = int(np.argmin(cost))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    m = float(minimize_scalar(lambda x: solve(x)[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10}).x)
    k1, k2 = solve(m)[1]
    return [float(k1) if k1 > 0 else float(f.max() / t[-1] ** m), float(k2), m]


def _initial(model: str, t: np.ndarray, f: np.ndarray) -> list[float]:
    """Starting values from the linearised forms of each model."""
    mid = float(np.interp(50.0, f, t)) if f.max() >= 50 else float(t[-1]) * 50.0 / max(float(f.max()), 1e-9)
    if model == "first-order":
        return [math.log(2.0) / mid]
    if model == "Hixson-Crowell":
        return [(1.0 - 0.5 ** (1 / 3)) / mid]
    if model == "Weibull":
        return [mid / math.log(2.0), 1.0]
    if model == "Hopfenberg":
        return [(1.0 - 0.5 ** 0.5) / mid, 2.0]
    if model == "Baker-Lonsdale":
        return [(1.5 * (1.0 - 0.5 ** (2.0 / 3.0)) - 0.5) / mid]
    if model == "Gompertz":
        return [math.log(2.0) * mid, 1.0]
    if model == "Peppas-Sahlin":
        return _peppas_sahlin_start(t, f)
    ok = (f > 0) & (t > 0)
    if ok.sum() >= 2:
        n, log_k = np.polyfit(np.log(t[ok]), np.log(f[ok]), 1)
        return [math.exp(log_k), float(np.clip(n, 0.05, 3.0))]
    return [float(f.max() / t[-1]), 1.0]


def _fit_one(model: _Model, t: np.ndarray, f: np.ndarray, time_unit: str) -> ModelFit:
    units = {p: u.format(t=time_unit) for p, u in zip(model.params, model.units)}
    p = len(model.params)
    if t.size < p + 2:
        return ModelFit(model.name, {}, units, math.nan, math.nan,
                        math.nan, int(t.size), note=f"{t.size} points; the fit needs at least {p + 2}")
    if model.name == "zero-order":
        x = [float(np.dot(t, f) / np.dot(t, t))]
    elif model.name == "Higuchi":
        x = [float(np.dot(np.sqrt(t), f) / np.sum(t))]
    else:
        # fit in log-parameters (positive ones): their scales differ by decades; signed ones as they are
        logs = np.array([p not in model.signed for p in model.params])
        start = np.array(_initial(model.name, t, f), dtype=float)

        def params_of(q):
            return np.where(logs, np.exp(np.where(logs, q, 0.0)), q)

        x0 = np.where(logs, np.log(np.where(logs, start, 1.0)), start)
        with np.errstate(over="ignore", invalid="ignore"):
            sol = least_squares(lambda q: model.function(t, *params_of(q)) - f, x0, method="lm", xtol=1e-12,
                                ftol=1e-12, gtol=1e-12, max_nfev=4000)
        if not sol.success or not np.all(np.isfinite(sol.fun)):
            return ModelFit(model.name, {}, units, math.nan, math.nan, math.nan, int(t.size),
                            note=f"least squares did not converge: {sol.message}")
        x = [float(v) for v in params_of(sol.x)]
    resid = model.function(t, *x) - f
    ssr = float(np.dot(resid, resid))
    sst = float(np.sum((f - f.mean()) ** 2))
    r2 = 1.0 - ssr / sst if sst > 0 else math.nan
    n = t.size
    r2_adj = 1.0 - (1.0 - r2) * (n - 1) / (n - p)
    aic = n * math.log(max(ssr, _SSR_FLOOR) / n) + 2 * p
    return ModelFit(model.name, dict(zip(model.params, x)), units, r2, r2_adj, aic, int(n))


def fit_release_models(profile: ReleaseProfile) -> tuple[ModelFit, ...]:
    """Fit every model of ``MODELS`` and rank them by AIC.

    Parameters
    ----------
    profile : ReleaseProfile
        The curve; percent released is relative to ``profile.amount_total`` (its weighed mass when given).

    Returns
    -------
    tuple of ModelFit
        Ranked fits first (rank 1 = lowest AIC), then the unranked ones (Korsmeyer-Peppas and Peppas-Sahlin
        when their 60 % range is not the whole curve, failed fits), each with a ``note``.

    Raises
    ------
    AnalysisError
        A curve with no positive total, or fewer than 3 points after time zero.
    """
    total = profile.amount_total
    if not total > 0:
        raise AnalysisError(f"{profile.label}: total release {total:g} {profile.amount_unit}; "
                            f"model fits need a positive total")
    keep = profile.t > 0
    t = profile.t[keep]
    f = 100.0 * profile.released[keep] / total
    if t.size < 3:
        raise AnalysisError(f"{profile.label}: {t.size} points after time zero; model fits need at least 3")
    fits = []
    early = f <= KP_LIMIT_PCT
    for model in MODELS:
        if model.early_only:
            fit = _fit_one(model, t[early], f[early], profile.time_unit)
            if not early.all() and not fit.note:
                fit = replace(fit, note=f"fitted on the {fit.n_points} points up to {KP_LIMIT_PCT:g} %; "
                                      f"its AIC is not comparable with the whole-curve fits")
        else:
            fit = _fit_one(model, t, f, profile.time_unit)
        fits.append(fit)
    ranked = sorted((x for x in fits if not x.note and math.isfinite(x.aic)), key=lambda x: x.aic)
    rest = [x for x in fits if x not in ranked]
    return tuple(replace(x, rank=i + 1) for i, x in enumerate(ranked)) + tuple(rest)


def best_fit(fits: tuple[ModelFit, ...]) -> ModelFit | None:
    """The rank-1 fit of :func:`fit_release_models`, or None if no model could be ranked."""
    return next((x for x in fits if x.rank == 1), None)
