"""A lean limited-memory BFGS for unconstrained minimisation, driven by reverse communication.

The paper solves eq. (4) with Knitro's L-BFGS (section 3.3) and reports its dense linear algebra as
the bottleneck (~8 s of ~10.5 s per iteration at 256^3, section 5.2). Here the optimiser does only
what an iteration needs, on arrays allocated once:

- the search direction ``d = -H g`` by the two-loop recursion (Nocedal and Wright, *Numerical
  Optimization*, 2nd ed., algorithm 7.4) written in place into ``d``, one fused pass per stored pair
  (``d += a x`` and the next pair's dot product with the updated ``d``), over the stored pairs
  ``s_i = x_{i+1} - x_i``, ``y_i = g_{i+1} - g_i`` (ring buffers of ``memory`` rows),
  ``H_0 = gamma I`` with ``gamma = s^T y / y^T y`` of the newest pair (their eq. 7.20);
- a line search along ``d`` by one of two rules (`LINE_SEARCHES`, `LbfgsSettings.line_search`):

  - "luksan" (the default): the rule of Luksan and Vlcek's PLIS, which nlopt's LD_LBFGS runs
    (nlopt ``src/algs/luksan``). The first trial is the unit step (along ``-g`` after a reset); a
    step is accepted on sufficient decrease ``f(x + a d) - f(x) <= c1 a g^T d`` together with the
    weak curvature condition ``g(x + a d)^T d >= c2 g^T d`` (c2 = 0.8), and once a trial has failed
    the decrease test, on sufficient decrease alone. New trials come from safeguarded model
    functions of the two latest points (cubic, else secant, else quadratic; `_model_step`). A
    search that fails after 10 model steps, or a pair with ``s^T y <= 0``, or a direction that is
    not a uniform descent direction (``g^T d > -1e-4 |g| |d|``), resets the memory to steepest
    descent; a failing steepest-descent search ends with `STALLED`. This evaluates the designs
    nlopt's LD_LBFGS evaluates, bit for bit, until nlopt ends a session on a stopping test of its
    own once J no longer changes (tests/design/inverse/test_lbfgs.py checks it);
  - "strong-wolfe": a step satisfying the strong Wolfe conditions
    ``f(x + a d) <= f(x) + c1 a g^T d`` and ``|g(x + a d)^T d| <= c2 |g^T d|`` (Nocedal and
    Wright, eq. 3.7; bracketing and zoom of algorithms 3.5-3.6 with safeguarded cubic
    interpolation, c2 = 0.5), a first step of `LbfgsSettings.first_step` without curvature pairs,
    and the lowest point of a failed search kept.

Reverse communication: the caller evaluates ``f`` at `Lbfgs.x_trial`, writes the gradient into
`Lbfgs.g_trial` and calls `Lbfgs.tell`. The whole state between two evaluations is a handful of
arrays and scalars (`Lbfgs.state`), so a run checkpointed after any evaluation and restored with
`Lbfgs.from_state` asks for exactly the points the uninterrupted run would have asked for.

The cost per evaluation is about ``4 m N`` flops in the two loops, one pass for the trial point and
one dot product for the directional derivative (N variables, m pairs); its share of an iteration:
docs/benchmarks.md#inverse-design. The vector kernels are single-threaded numba loops rather than
BLAS, whose threaded vector kernels spin rather than compute when the cores are busy with the
objective or other jobs. Every sum runs in index order with one accumulator, the order of nlopt's own
loops: every run, resumed or not, is bit-for-bit the same, and the "luksan" rule reproduces nlopt's
iterates.
"""
from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np
from numba import njit

log = logging.getLogger(__name__)

LINE_SEARCHES = ("luksan", "strong-wolfe")
"""`LbfgsSettings.line_search` rules (module doc); the first is the default."""
CURVATURE_C2 = {"luksan": 0.8, "strong-wolfe": 0.5}
"""Default curvature constant c2 of each rule: PLIS's ``tolp``; for the strong rule, of 0.5, 0.8 and 0.9
the one with the better designs on the sample shapes (studies/optimizer_quality.py,
docs/benchmarks.md#studies)."""
MODEL_STEPS = 10
"""Extrapolations or interpolations a "luksan" search may make before it fails (PLIS's ``mred``)."""
SEARCH, STEP, CONVERGED, STALLED = "search", "step", "converged", "stalled"
"""What `Lbfgs.tell` reports: another trial on the same line, an accepted step, a stationary point
or convergence by the tolerances, or a line search that found no acceptable step."""


@dataclass(frozen=True)
class LbfgsSettings:
    """Settings of `Lbfgs`.

    Parameters
    ----------
    memory : int
        Correction pairs m kept (memory 2 m N doubles).
    c1, c2 : float
        Sufficient-decrease and curvature constants, ``0 < c1 < c2 < 1``; c2 None takes the rule's
        `CURVATURE_C2`.
    max_search_evals : int
        Evaluations one "strong-wolfe" search may use before it is declared stalled.
    first_step : float
        "strong-wolfe" only: largest change of any variable on a step without curvature pairs (the
        first, and after a reset), in the variables' units (rad of the cosine map, default 2; with
        beta continuation every stage starts afresh, so this step recurs; compared with
        studies/optimizer_quality.py, docs/benchmarks.md#studies).
    ftol_rel, xtol_rel : float
        Convergence when an accepted step changes f by at most ``ftol_rel |f|`` or x by at most
        ``xtol_rel |x|`` (Euclidean norms); 0 disables.
    line_search : str
        One of `LINE_SEARCHES`.
    """

    memory: int = 10
    c1: float = 1e-4
    c2: float | None = None
    max_search_evals: int = 20
    first_step: float = 2.0
    ftol_rel: float = 0.0
    xtol_rel: float = 0.0
    line_search: str = LINE_SEARCHES[0]

    def __post_init__(self) -> None:
        if self.line_search not in LINE_SEARCHES:
            raise ValueError(f"line_search must be one of {LINE_SEARCHES}, got {self.line_search!r}")
        if self.c2 is None:
            object.__setattr__(self, "c2", CURVATURE_C2[self.line_search])
        if not 1 <= self.memory <= 1000:
            raise ValueError(f"memory must be in [1, 1000] pairs, got {self.memory}")
        if not 0.0 < self.c1 < self.c2 < 1.0:
            raise ValueError(f"need 0 < c1 < c2 < 1, got c1 = {self.c1}, c2 = {self.c2}")
        if self.max_search_evals < 2 or not self.first_step > 0:
            raise ValueError(f"need max_search_evals >= 2 and first_step > 0, got {self.max_search_evals}, "
                             f"{self.first_step}")
        if self.ftol_rel < 0 or self.xtol_rel < 0:
            raise ValueError(f"tolerances must be >= 0, got ftol_rel {self.ftol_rel}, xtol_rel {self.xtol_rel}")


def _cubic_min(a: float, fa: float, da: float, b: float, fb: float, db: float) -> float:
    """Minimiser of the cubic through (a, fa, f'(a) = da) and (b, fb, db); nan if it has none."""
    d1 = da + db - 3.0 * (fa - fb) / (a - b)
    disc = d1 * d1 - da * db
    if not disc >= 0.0:
        return math.nan
    d2 = math.copysign(math.sqrt(disc), b - a)
    den = db - da + 2.0 * d2
    return b - (b - a) * (db + d2 - d1) / den if den != 0.0 else math.nan


@njit(cache=True, nogil=True)
def _axpy_dot(a: float, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> float:
    """``y += a x`` in place and return ``z . y`` (new y), in one pass; sum in index order."""
    total = 0.0
    for i in range(y.size):
        y[i] = y[i] + a * x[i]
        total += z[i] * y[i]
    return total


@njit(cache=True, nogil=True)
def _scale_dot(a: float, y: np.ndarray, z: np.ndarray) -> float:
    """``y *= a`` in place and return ``z . y`` (new y), in one pass; sum in index order."""
    total = 0.0
    for i in range(y.size):
        y[i] = a * y[i]
        total += z[i] * y[i]
    return total


@njit(cache=True, nogil=True)
def _dot(x: np.ndarray, y: np.ndarray) -> float:
    """``x . y``, summed in index order."""
    total = 0.0
    for i in range(x.size):
        total += x[i] * y[i]
    return total


def _model_step(rl: float, fl: float, pl: float, ru: float, fu: float, pu: float, extrapolate: bool) -> float:
    """Next "luksan" trial from the points (rl, fl, pl), (ru, fu, pu) (step, value, slope), rl < ru.

    The minimiser of the first model with a usable one (cubic through both values and slopes; the
    secant of the slopes; the quadratic through both values and the slope at rl), written with
    ``A = (fu - fl) / (pl (ru - rl))``, ``B = pu / pl`` as ``rl + (ru - rl) / den``. Extrapolating:
    within [1.1 ru, 1000 ru], else 4 ru. Interpolating: within 1% (rl = 0) or 10% of the bracket
    from rl and 10% from ru, else its midpoint. nan if pl >= 0 or ru <= rl (no descent to model).
    """
    if not (pl < 0.0 and ru > rl):
        return math.nan
    if math.isfinite(fu) and math.isfinite(pu) and fu < 1e20:
        a = (fu - fl) / (pl * (ru - rl))
        b = pu / pl
        for model in ("cubic", "secant", "quadratic"):
            if model == "cubic":
                c, d = b - a * 2.0 + 1.0, b - a * 3.0 + 2.0
                disc = d * d - c * 3.0
                if disc < 0.0:
                    continue
                den = d + math.sqrt(disc)
            else:
                den = 1.0 - b if model == "secant" else (1.0 - a) * 2.0
            if extrapolate and 0.0 < den < 1.0:
                return min(max(rl + (ru - rl) / den, ru * 1.1), ru * 1e3)
            if not extrapolate and den > 1.0:
                r = max(rl + (ru - rl) / den, rl + (ru - rl) * (0.01 if rl == 0.0 else 0.1))
                return min(r, rl + (ru - rl) * 0.9)
    return ru * 4.0 if extrapolate else (rl + ru) * 0.5


# scalars of the state, in the order `Lbfgs.state` stores them
_SCALARS = ("f", "gamma", "head", "count", "iterations", "restarts", "f_restart", "initialised",
            "stp", "f0", "dg0", "nevals", "bracketed", "a_lo", "f_lo", "dg_lo", "a_hi", "f_hi", "dg_hi",
            "model_steps", "stp_min", "stp_max")


class Lbfgs:
    """L-BFGS state for minimising f over ``x`` (1D, float64), one evaluation at a time.

    Parameters
    ----------
    x0 : (N,) array_like of float
        Starting point; the first point asked for.
    settings : LbfgsSettings, optional

    Attributes
    ----------
    x_trial : (N,) ndarray of float
        The point to evaluate next (read it, do not write it).
    g_trial : (N,) ndarray of float
        Where the caller writes the gradient at `x_trial` before `tell`. Buffers are exchanged
        internally: read the attribute afresh before every evaluation.
    x, f, g
        The current iterate, its value and its gradient (after the first `tell`).
    iterations : int
        Accepted steps so far.
    restarts, f_restart
        The caller's bookkeeping of restarted sessions, saved with the state: how many sessions ran
        before this one (0), and the best value known when it began (inf).
    """

    def __init__(self, x0: np.ndarray, settings: LbfgsSettings | None = None) -> None:
        self.settings = settings or LbfgsSettings()
        x0 = np.asarray(x0, dtype=np.float64)
        if x0.ndim != 1 or x0.size == 0 or not np.all(np.isfinite(x0)):
            raise ValueError(f"x0 must be a non-empty finite 1D array, got shape {x0.shape}")
        n, m = x0.size, self.settings.memory
        self.x = x0.copy()
        self.x_trial = x0.copy()
        self.g = np.zeros(n)
        self.g_trial = np.zeros(n)
        self.g_lo = np.zeros(n)  # gradient at the low end of the line-search bracket
        self.d = np.zeros(n)
        self.s = np.empty((m, n))
        self.y = np.empty((m, n))
        self.rho = np.zeros(m)  # 1 / (s_i^T y_i)
        self._alpha = np.zeros(m)
        self.f = math.inf
        self.gamma = 0.0  # 0: no curvature estimate yet
        self.head = 0  # ring slot of the next pair
        self.count = 0  # pairs stored
        self.iterations = 0
        self.restarts = 0
        self.f_restart = math.inf
        self.initialised = False  # f and g at x known
        # line search along d from x: phi(a) = f(x + a d); lo/hi bracket the accepted step
        self.stp = self.f0 = self.dg0 = 0.0
        self.nevals = 0
        self.bracketed = False
        self.a_lo = self.f_lo = self.dg_lo = self.a_hi = self.f_hi = self.dg_hi = 0.0
        self.model_steps = 0  # "luksan": extrapolations (< 0) or interpolations (> 0) so far
        self.stp_min, self.stp_max = 0.0, math.inf  # "luksan": step bounds of the search

    # -- the iteration -------------------------------------------------------------------------
    def tell(self, f_trial: float) -> str:
        """Take ``f(x_trial)`` (and the gradient already written to `g_trial`); prepare the next trial.

        Returns
        -------
        str
            `SEARCH` (the line search continues), `STEP` (a step was accepted and a new line
            search begun), `CONVERGED` or `STALLED`. After the last two, `x`/`f`/`g` hold the best
            point found and no trial is pending.
        """
        f_trial = float(f_trial)
        if not self.initialised:
            if not math.isfinite(f_trial):
                raise ValueError(f"f at the starting point is {f_trial}")
            self.f = f_trial
            self.x, self.x_trial = self.x_trial, self.x
            self.g, self.g_trial = self.g_trial, self.g
            self.initialised = True
            return self._begin_search()
        return self._search(f_trial)

    def _begin_search(self) -> str:
        """Direction, initial step and first trial of a new line search (or CONVERGED)."""
        self._direction()
        dg0 = _dot(self.g, self.d)
        if self.settings.line_search == "luksan":
            g_norm = math.sqrt(_dot(self.g, self.g))
            d_norm = math.sqrt(_dot(self.d, self.d)) if self.count else g_norm
            if self.count and not dg0 + 1e-4 * g_norm * d_norm <= 0.0:  # not a uniform descent direction
                return self._reset()
            if not d_norm > 0.0:
                return CONVERGED
            self.stp_min = 1e-10 * g_norm / d_norm
            self.stp_max = min(1e10 * g_norm / d_norm, 1e16 / d_norm)
            self.stp = min(max(1.0, self.stp_min), self.stp_max)
            self.model_steps = 0
        else:
            if not dg0 < 0.0:  # H is positive definite, so only g = 0 gets here after a reset
                self._forget()
                np.negative(self.g, out=self.d)
                dg0 = -_dot(self.g, self.g)
                if not dg0 < 0.0:
                    return CONVERGED
            # the quasi-Newton step is scaled by H_0 = gamma I
            self.stp = 1.0 if self.gamma > 0.0 else self.settings.first_step / float(np.max(np.abs(self.d)))
        self.f0, self.dg0 = self.f, dg0
        self.nevals = 0
        self.bracketed = False
        self.a_lo, self.f_lo, self.dg_lo = 0.0, self.f0, self.dg0
        self.a_hi = self.f_hi = self.dg_hi = 0.0
        self._set_trial()
        return STEP

    def _forget(self) -> None:
        """Drop the curvature pairs: the next direction is steepest descent."""
        self.count = self.head = 0
        self.gamma = 0.0

    def _reset(self) -> str:
        """Forget the curvature pairs and begin a steepest-descent search from `x`."""
        self._forget()
        return self._begin_search()

    def _direction(self) -> None:
        """``d = -H g`` by the two-loop recursion over the stored pairs, in place."""
        d, m, s, y = self.d, self.settings.memory, self.s, self.y
        np.negative(self.g, out=d)
        if self.count == 0:
            return
        order = [(self.head - 1 - i) % m for i in range(self.count)]  # newest first
        dot = _dot(s[order[0]], d)
        for j, i in enumerate(order):  # q -= alpha_i y_i, alpha_i = rho_i s_i^T q
            a = self.rho[i] * dot
            self._alpha[i] = a
            dot = _axpy_dot(-a, y[i], d, s[order[j + 1]] if j + 1 < len(order) else y[i])
        back = order[::-1]
        dot = _scale_dot(self.gamma, d, y[back[0]])  # r = H_0 q, and y_oldest^T r
        for j, i in enumerate(back):  # r += (alpha_i - beta_i) s_i, beta_i = rho_i y_i^T r
            b = self.rho[i] * dot
            dot = _axpy_dot(self._alpha[i] - b, s[i], d, y[back[j + 1]] if j + 1 < len(back) else s[i])

    def _set_trial(self) -> None:
        np.multiply(self.d, self.stp, out=self.x_trial)
        self.x_trial += self.x

    def _search(self, ft: float) -> str:
        """One step of the line search (`LbfgsSettings.line_search`)."""
        if self.settings.line_search == "luksan":
            return self._search_luksan(ft)
        return self._search_strong_wolfe(ft)

    def _search_luksan(self, ft: float) -> str:
        """One step of the "luksan" line search (module doc)."""
        cfg = self.settings
        a, dg = self.stp, _dot(self.g_trial, self.d) if math.isfinite(ft) else math.nan
        self.nevals += 1
        df = ft - self.f0
        decrease = (df <= cfg.c1 * a * self.dg0  # sufficient decrease, or a flat spot reached
                    or (abs(dg) <= abs(self.dg0) * 0.01 and -df >= abs(self.f0) * 1e-11)
                    or (abs(dg) <= abs(self.dg0) * 0.5 and abs(df) <= abs(self.f0) * 2e-13))
        curvature = self.bracketed or dg >= cfg.c2 * self.dg0
        if a <= self.stp_min and self.count and not decrease:
            return self._fail()
        if decrease and (curvature or a >= self.stp_max):
            return self._accept(ft)
        if abs(self.model_steps) >= MODEL_STEPS:
            return self._fail()
        if decrease:  # still steeply descending: extrapolate from the last two trials
            lo = (self.a_lo, self.f_lo, self.dg_lo)
            self._set_lo(a, ft, dg)
            self.stp = min(_model_step(*lo, a, ft, dg, True), self.stp_max)
            self.model_steps -= 1
        else:  # the step is too long: interpolate between the last decrease (or 0) and it
            if not self.bracketed:
                self.bracketed, self.model_steps = True, 0
            self.a_hi, self.f_hi, self.dg_hi = a, ft, dg
            self.stp = _model_step(self.a_lo, self.f_lo, self.dg_lo, a, ft, dg, False)
            self.model_steps += 1
        if not math.isfinite(self.stp):
            return self._fail()
        self._set_trial()
        return SEARCH

    def _search_strong_wolfe(self, ft: float) -> str:
        """One step of the strong-Wolfe line search (Nocedal and Wright, algorithms 3.5 and 3.6)."""
        cfg = self.settings
        a, dg = self.stp, _dot(self.g_trial, self.d) if math.isfinite(ft) else math.nan
        self.nevals += 1
        armijo = math.isfinite(ft) and ft <= self.f0 + cfg.c1 * a * self.dg0
        if armijo and abs(dg) <= -cfg.c2 * self.dg0:
            return self._accept(ft)
        if not self.bracketed:
            if not armijo or (self.nevals > 1 and ft >= self.f_lo):
                self._set_hi(a, ft, dg)  # the minimiser lies between lo and this step
            elif dg >= 0.0:
                self.a_hi, self.f_hi, self.dg_hi = self.a_lo, self.f_lo, self.dg_lo
                self._set_lo(a, ft, dg)
                self.bracketed = True
            else:  # still descending: extrapolate
                lo = (self.a_lo, self.f_lo, self.dg_lo)
                self._set_lo(a, ft, dg)
                step = a - lo[0]
                c = _cubic_min(*lo, a, ft, dg)
                self.stp = c if a + 1.1 * step <= c <= a + 4.0 * step else a + 4.0 * step
                return self._next_trial()
        elif not armijo or ft >= self.f_lo:
            self.a_hi, self.f_hi, self.dg_hi = a, ft, dg
        else:
            if dg * (self.a_hi - self.a_lo) >= 0.0:
                self.a_hi, self.f_hi, self.dg_hi = self.a_lo, self.f_lo, self.dg_lo
            self._set_lo(a, ft, dg)
        # zoom: a safeguarded cubic step strictly inside the bracket
        lo, hi = min(self.a_lo, self.a_hi), max(self.a_lo, self.a_hi)
        width = hi - lo
        if width <= 1e-12 * hi:
            return self._fail()
        if math.isfinite(self.f_hi) and math.isfinite(self.dg_hi):
            c = _cubic_min(self.a_lo, self.f_lo, self.dg_lo, self.a_hi, self.f_hi, self.dg_hi)
        else:
            c = math.nan
        self.stp = c if lo + 0.1 * width <= c <= hi - 0.1 * width else 0.5 * (lo + hi)
        return self._next_trial()

    def _set_hi(self, a: float, ft: float, dg: float) -> None:
        self.a_hi, self.f_hi, self.dg_hi = a, ft, dg
        self.bracketed = True

    def _set_lo(self, a: float, ft: float, dg: float) -> None:
        self.a_lo, self.f_lo, self.dg_lo = a, ft, dg
        self.g_lo, self.g_trial = self.g_trial, self.g_lo

    def _next_trial(self) -> str:
        if self.nevals >= self.settings.max_search_evals:
            return self._fail()
        self._set_trial()
        return SEARCH

    def _fail(self) -> str:
        """No acceptable step. "luksan": stay at `x` and reset to steepest descent, or end STALLED
        if this was a steepest-descent search. "strong-wolfe": move to the lowest point of the
        search (if below f0), then STALLED."""
        if self.settings.line_search == "luksan":
            log.debug("line search failed after %d evaluations", self.nevals)
            if self.count == 0:
                return STALLED
            outcome = self._reset()
            return SEARCH if outcome == STEP else outcome
        if self.a_lo > 0.0:
            self.stp = self.a_lo
            self._set_trial()
            self.x, self.x_trial = self.x_trial, self.x
            self.g, self.g_lo = self.g_lo, self.g
            self.f = self.f_lo
        log.debug("line search stalled after %d evaluations (step %.3g)", self.nevals, self.a_lo)
        return STALLED

    def _accept(self, ft: float) -> str:
        """Store the pair (s, y) of the accepted step and begin the next line search."""
        cfg, slot = self.settings, self.head
        s, y = self.s[slot], self.y[slot]
        np.subtract(self.x_trial, self.x, out=s)
        np.subtract(self.g_trial, self.g, out=y)
        sy, yy = _dot(s, y), _dot(y, y)
        # the strong Wolfe curvature condition gives sy > 0; "luksan" resets the memory without it
        if sy > 0.0 and (cfg.line_search == "luksan" or sy > 1e-12 * yy):
            self.rho[slot] = 1.0 / sy
            self.gamma = sy / yy
            self.head = (slot + 1) % cfg.memory
            self.count = min(self.count + 1, cfg.memory)
        elif cfg.line_search == "luksan":
            self._forget()
        f_old = self.f
        small_x = cfg.xtol_rel > 0 and np.linalg.norm(s) <= cfg.xtol_rel * np.linalg.norm(self.x_trial)
        self.x, self.x_trial = self.x_trial, self.x
        self.g, self.g_trial = self.g_trial, self.g
        self.f = ft
        self.iterations += 1
        if small_x or (cfg.ftol_rel > 0 and abs(f_old - ft) <= cfg.ftol_rel * abs(ft)):
            return CONVERGED
        return self._begin_search()

    # -- checkpoints ---------------------------------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        """Everything `from_state` needs, as arrays (for ``np.savez``); pairs in ring order."""
        k = self.count  # the ring fills from slot 0, so the stored pairs are the first k slots
        return {"x": self.x, "g": self.g, "d": self.d, "g_lo": self.g_lo,
                "s": self.s[:k], "y": self.y[:k], "rho": self.rho[:k],
                "scalars": np.array([float(getattr(self, name)) for name in _SCALARS]),
                "settings": np.array([float(LINE_SEARCHES.index(v)) if name == "line_search" else float(v)
                                      for name, v in asdict(self.settings).items()])}

    @classmethod
    def from_state(cls, state: dict[str, np.ndarray]) -> "Lbfgs":
        """The optimiser saved by `state`; its next trial point is the saved run's next one."""
        values = dict(zip(asdict(LbfgsSettings()).items(), np.asarray(state["settings"])))
        stored = {name: LINE_SEARCHES[int(value)] if name == "line_search" else type(default)(value)
                  for (name, default), value in values.items()}
        stored.setdefault("line_search", "strong-wolfe")  # states saved before the rule was a setting
        settings = LbfgsSettings(**stored)
        opt = cls(np.asarray(state["x"]), settings)
        for name, value in zip(_SCALARS, np.asarray(state["scalars"])):
            current = getattr(opt, name)
            setattr(opt, name, type(current)(value))
        k = opt.count
        opt.g[:] = state["g"]
        opt.d[:] = state["d"]
        opt.g_lo[:] = state["g_lo"]
        opt.s[:k], opt.y[:k], opt.rho[:k] = state["s"], state["y"], state["rho"]
        if opt.initialised:
            opt._set_trial()
        return opt


@dataclass(frozen=True)
class MinimizeResult:
    """Outcome of `minimize`: the best point, its value, the reason it ended and the work done."""

    x: np.ndarray
    f: float
    status: str
    evaluations: int
    iterations: int


def minimize(fun: Callable[[np.ndarray, np.ndarray], float], x0: np.ndarray, *, max_evals: int = 1000,
             settings: LbfgsSettings | None = None,
             on_step: Callable[[Lbfgs], None] | None = None) -> MinimizeResult:
    """Minimise ``fun(x, grad) -> f`` (gradient written into ``grad``) from ``x0``.

    Ends at `CONVERGED`, `STALLED` or after ``max_evals`` evaluations ("max_evals");
    ``on_step(opt)`` is called after every accepted step.
    """
    opt = Lbfgs(x0, settings)
    status, evals = "max_evals", 0
    while evals < max_evals:
        value = fun(opt.x_trial, opt.g_trial)
        evals += 1
        outcome = opt.tell(value)
        if outcome == STEP and opt.iterations and on_step is not None:
            on_step(opt)
        if outcome in (CONVERGED, STALLED):
            status = outcome
            break
    return MinimizeResult(opt.x.copy(), opt.f, status, evals, opt.iterations)
