"""analysis.release_models: fits recover known parameters, agree with scipy's curve_fit on noisy data,
goodness-of-fit numbers recomputed independently, AIC ranking and the Korsmeyer-Peppas 60 % range."""
import math

import numpy as np
import pytest
from scipy.optimize import curve_fit

from analysis import AnalysisError
from analysis.profile import ReleaseProfile
from analysis.release_models import BAKER_LONSDALE_END, MODEL_NAMES, best_fit, fit_release_models

T_MIN = np.linspace(0, 240, 49)  # every 5 min for 4 h

TRUTH = {
    "zero-order": (lambda t: 0.35 * t, {"k0": 0.35}),
    "first-order": (lambda t: 100 * (1 - np.exp(-0.021 * t)), {"k1": 0.021}),
    "Higuchi": (lambda t: 6.2 * np.sqrt(t), {"kH": 6.2}),
    "Hixson-Crowell": (lambda t: 100 * (1 - np.clip(1 - 0.0035 * t, 0, None) ** 3), {"kHC": 0.0035}),
    "Weibull": (lambda t: 100 * (1 - np.exp(-(t / 70.0) ** 1.6)), {"td": 70.0, "beta": 1.6}),
    "Hopfenberg": (lambda t: 100 * (1 - np.clip(1 - 0.0032 * t, 0, None) ** 1.7), {"kHB": 0.0032, "n": 1.7}),
    "Gompertz": (lambda t: 100 * np.exp(-45.0 * np.where(t > 0, t, 1.0) ** -1.1), {"alpha": 45.0, "beta": 1.1}),
}
TIES = {"first-order": ("Weibull", {"beta": 1.0}), "Hixson-Crowell": ("Hopfenberg", {"n": 3.0})}
"""Models that contain another as a special case tie with it at round-off on its noise-free curve."""


def _baker_lonsdale_pct(t, kbl):
    """Independent inverse of 3/2 (1 - (1 - F)^(2/3)) - F = kBL t: the real root of the cubic in
    u = (1 - F)^(1/3) inside [0, 1], by numpy's polynomial roots."""
    out = []
    for y in np.minimum(kbl * np.asarray(t, float), BAKER_LONSDALE_END):
        roots = np.roots([1.0, -1.5, 0.0, 0.5 - y])
        u = min(r.real for r in roots if abs(r.imag) < 1e-9 and -1e-12 <= r.real <= 1 + 1e-12)
        out.append(100 * (1 - max(u, 0.0) ** 3))
    return np.array(out)


TRUTH["Baker-Lonsdale"] = (lambda t: _baker_lonsdale_pct(t, 0.0019), {"kBL": 0.0019})


def _fits(t, pct):
    return {f.model: f for f in fit_release_models(ReleaseProfile(t, pct, "min", "%", 100.0, "data"))}


@pytest.mark.parametrize("model", sorted(TRUTH))
def test_noise_free_data_give_back_the_parameters(model):
    curve, params = TRUTH[model]
    fits = _fits(T_MIN, curve(T_MIN))
    fit = fits[model]
    for name, value in params.items():
        assert fit.params[name] == pytest.approx(value, rel=1e-6), name
    assert fit.r2 == pytest.approx(1.0, abs=1e-9)
    if model in TIES:  # Weibull with beta = 1 and Hopfenberg with n = 3 are the same curves
        other, special = TIES[model]
        for name, value in special.items():
            assert fits[other].params[name] == pytest.approx(value, rel=1e-6)
        assert {fit.rank, fits[other].rank} == {1, 2}
    else:
        assert fit.rank == 1  # an exact fit has the lowest AIC


def test_korsmeyer_peppas_uses_the_first_60_percent_and_matches_a_log_log_line():
    t = T_MIN
    pct = np.minimum(2.0 * t ** 0.75, 100.0)  # power law up to 100 %
    fit = _fits(t, pct)["Korsmeyer-Peppas"]
    early = (t > 0) & (pct <= 60)
    assert fit.n_points == int(early.sum())
    slope, intercept = np.polyfit(np.log(t[early]), np.log(pct[early]), 1)  # independent: linearised form
    assert fit.params["n"] == pytest.approx(slope, rel=1e-6)
    assert fit.params["kKP"] == pytest.approx(math.exp(intercept), rel=1e-6)
    assert fit.rank is None and "not comparable" in fit.note
    low = _fits(t, 0.2 * t ** 0.9)  # the whole curve stays below 60 %: ranked (Peppas-Sahlin with k2 = 0 ties)
    assert low["Korsmeyer-Peppas"].note == "" and {low["Korsmeyer-Peppas"].rank, low["Peppas-Sahlin"].rank} == {1, 2}
    assert low["Peppas-Sahlin"].params["k2"] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("k1, k2, m", [(3.1, 0.05, 0.42), (1.2, -0.0008, 0.8)])
def test_peppas_sahlin_gives_back_fickian_and_relaxation_terms_of_either_sign(k1, k2, m):
    t = T_MIN
    pct = np.minimum(k1 * t ** m + k2 * t ** (2 * m), 100.0)
    fit = _fits(t, pct)["Peppas-Sahlin"]
    early = (t > 0) & (pct <= 60)
    assert fit.n_points == int(early.sum())
    assert [fit.params[p] for p in ("k1", "k2", "m")] == pytest.approx([k1, k2, m], rel=1e-6)


def test_noisy_fits_agree_with_scipy_curve_fit_and_goodness_of_fit_recomputed():
    rng = np.random.default_rng(11)
    t = T_MIN[1:]
    pct = 100 * (1 - np.exp(-(t / 80.0) ** 1.3)) + rng.normal(0, 0.6, t.size)
    fits = _fits(t, pct)
    checks = {
        "Weibull": (lambda x, td, b: 100 * (1 - np.exp(-(x / td) ** b)), [60.0, 1.0], ("td", "beta")),
        "first-order": (lambda x, k: 100 * (1 - np.exp(-k * x)), [0.01], ("k1",)),
        "Hixson-Crowell": (lambda x, k: 100 * (1 - np.clip(1 - k * x, 0, None) ** 3), [0.002], ("kHC",)),
        "Higuchi": (lambda x, k: k * np.sqrt(x), [1.0], ("kH",)),
        "zero-order": (lambda x, k: k * x, [1.0], ("k0",)),
        "Hopfenberg": (lambda x, k, n: 100 * (1 - np.clip(1 - k * x, 0, None) ** n), [0.003, 2.0], ("kHB", "n")),
        "Gompertz": (lambda x, a, b: 100 * np.exp(-a * x ** -b), [60.0, 1.0], ("alpha", "beta")),
        "Baker-Lonsdale": (_baker_lonsdale_pct, [0.002], ("kBL",)),
    }
    for model, (f, p0, names) in checks.items():
        popt, _ = curve_fit(f, t, pct, p0=p0, method="trf", xtol=1e-14, ftol=1e-14, gtol=1e-14)
        ours = fits[model]
        for name, value in zip(names, popt):
            assert ours.params[name] == pytest.approx(value, rel=1e-5), (model, name)
        resid = pct - f(t, *popt)
        ssr, n, p = float(resid @ resid), t.size, len(names)
        r2 = 1 - ssr / float(np.sum((pct - pct.mean()) ** 2))
        assert ours.r2 == pytest.approx(r2, rel=1e-8)
        assert ours.r2_adj == pytest.approx(1 - (1 - r2) * (n - 1) / (n - p), rel=1e-8)
        assert ours.aic == pytest.approx(n * math.log(ssr / n) + 2 * p, rel=1e-6)
    assert best_fit(tuple(fits.values())).model == "Weibull"
    ranks = sorted(f.rank for f in fits.values() if f.rank is not None)
    assert ranks == list(range(1, len(ranks) + 1))


def test_fits_use_the_weighed_mass_and_report_units():
    t = T_MIN * 60.0  # seconds
    grams = 1.2 * (1 - np.exp(-t / 3000.0))  # 1.2 g of a 1.5 g object: 80 % at most
    fits = {f.model: f for f in fit_release_models(ReleaseProfile(t, grams, total=1.5))}
    weibull = fits["Weibull"]
    assert weibull.percent_at(np.array([1e9]))[0] == pytest.approx(100.0)
    assert fits["first-order"].units == {"k1": "1/s"}
    assert "k1 = " in fits["first-order"].describe()
    assert set(fits) == set(MODEL_NAMES)


def test_too_few_points_are_refused():
    with pytest.raises(AnalysisError, match="2 points after time zero"):
        fit_release_models(ReleaseProfile([0, 1, 2.0], [0, 1, 2]))
    short = {f.model: f for f in fit_release_models(ReleaseProfile([0, 1, 2, 3.0], [0, 10, 20, 30]))}
    assert short["Weibull"].note.startswith("3 points; the fit needs at least 4")
