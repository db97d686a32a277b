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
=================  ==========================================  ===============================

Each fit is ordinary least squares on the points with t > 0 (time zero fits every model exactly), with
R^2 = 1 - SSR/SST, adjusted R^2 = 1 - (1 - R^2)(n - 1)/(n - p) and AIC = n ln(SSR/n) + 2p. AIC compares
models only on the same points, so Korsmeyer-Peppas, fitted on the first 60 %, is ranked with the
others only when that is the whole curve; otherwise it is listed after them, unranked.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from analysis.errors import AnalysisError
from analysis.profile import ReleaseProfile

KP_LIMIT_PCT = 60.0
"""Korsmeyer-Peppas is fitted on the points up to this percent released."""
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


@dataclass(frozen=True)
class _Model:
    name: str
    function: Callable[..., np.ndarray]
    params: tuple[str, ...]
    units: tuple[str, ...]


MODELS = (
    _Model("zero-order", _zero, ("k0",), ("%/{t}",)),
    _Model("first-order", _first, ("k1",), ("1/{t}",)),
    _Model("Higuchi", _higuchi, ("kH",), ("%/{t}^0.5",)),
    _Model("Korsmeyer-Peppas", _peppas, ("kKP", "n"), ("%/{t}^n", "")),
    _Model("Hixson-Crowell", _hixson, ("kHC",), ("1/{t}",)),
    _Model("Weibull", _weibull, ("td", "beta"), ("{t}", "")),
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
        Points fitted (t > 0; F <= 60 % for Korsmeyer-Peppas).
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


def _initial(model: str, t: np.ndarray, f: np.ndarray) -> list[float]:
    """Starting values from the linearised forms of each model."""
    mid = float(np.interp(50.0, f, t)) if f.max() >= 50 else float(t[-1]) * 50.0 / max(float(f.max()), 1e-9)
    if model == "first-order":
        return [math.log(2.0) / mid]
    if model == "Hixson-Crowell":
        return [(1.0 - 0.5 ** (1 / 3)) / mid]
    if model == "Weibull":
        return [mid / math.log(2.0), 1.0]
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
        # fit in log-parameters: every parameter is positive, and their scales differ by decades
        x0 = np.log(_initial(model.name, t, f))
        sol = least_squares(lambda q: model.function(t, *np.exp(q)) - f, x0, method="lm", xtol=1e-12,
                            ftol=1e-12, gtol=1e-12, max_nfev=2000)
        if not sol.success:
            return ModelFit(model.name, {}, units, math.nan, math.nan, math.nan, int(t.size),
                            note=f"least squares did not converge: {sol.message}")
        x = [float(v) for v in np.exp(sol.x)]
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
        Ranked fits first (rank 1 = lowest AIC), then the unranked ones (Korsmeyer-Peppas when its 60 %
        range is not the whole curve, failed fits), each with a ``note``.

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
        if model.name == "Korsmeyer-Peppas":
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
