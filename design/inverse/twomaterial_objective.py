"""The objective of a two-material (drug and barrier) design and its exact gradient.

Variables. Two fields on the design space's variable grid (`design.inverse.spaces`): ``phi_hat``, where
material is, and ``f_hat``, the drug's share of it. Each is smoothed and projected as the one-material
density is (eq. 4's filter chain, `design.inverse.filters`), giving phi and f in [0, 1]; the drug
density is ``rho_d = phi f`` and the barrier's ``rho_b = phi (1 - f)``.

Slowness. The forward model's law (`design.forward.twomaterial`, eq. 2 with two materials) is linear in
the barrier density, ``n = rho_d + k rho_b + void n_min`` with k = 1 / s: a trace of a slow barrier already
multiplies a voxel's crossing time, so a grey drug voxel near a barrier is as slow as barrier and the
gradient in f says little but "no barrier here". The design uses a RAMP interpolation of the barrier
share b = 1 - f (Stolpe and Svanberg 2001),

    n = phi m(f) + (1 - phi) n_min,    m(f) = 1 + (k_d - 1) w(1 - f),    w(b) = b / (1 + q (1 - b)),

equal to the forward model's law for binary fields (w(0) = 0, w(1) = 1), with grey barrier shares
crossed much faster than their linear share (w(0.1) = 0.027 at q = 3). Only the drug releases: eq. (7)
weighs each voxel's ramp (eq. 6) by rho_d. k_d is the design's barrier slowness: 1 / s, capped at
`hold_slowness` (a barrier two print lines thick then holds for twice the horizon T: it is insoluble as
far as the curve sees), which is what an insoluble barrier (s = 0) is designed with; the printed design
is then judged by the forward model at the true s.

Objective (eq. 4 in relative units): J = J_fit + w_b J_binary + w_s J_skin with
``J_fit = (1/T) sum_k (C_k - C*_k)^2 dtau / C*_K^2``, ``J_binary = mean_i [phi (1 - phi) + phi f (1 - f)]`` and

    J_skin = sum_i rho_d,i g(c_i / w) / V*,    g(t) = t (1 - t) for t < 1, else 0,

where c_i is the least barrier between the bath and voxel i (eq. 5 on the slowness ``rho_b + (1 - rho_b)
n_min``, `design.forward.twomaterial.barrier_cover`'s field), w = `MIN_BARRIER_MM` (two print lines) and V*
the target's volume in voxels. It is zero for drug open to the bath (c = 0) and for drug behind a printable
barrier (c >= w), and positive for drug behind a skin thinner than a print holds: without it the optimiser
tunes the release with such skins, which the print cannot keep (`design.fabrication.twomaterial_print`).
The gradient runs through eq. (7), the adjoint sweep (eq. 10), the slowness law, the projection and the
smoothing filter, exactly (checked against finite differences, tests/design/inverse/test_twomaterial_gradient.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from design.errors import DesignError
from design.forward.fmm import march, march_adjoint
from design.forward.release import ramp_release, ramp_release_vjp
from design.forward.simulator import N_MIN
from design.inverse.filters import SmoothingFilter, project, project_adjoint
from design.inverse.twomaterial_targets import MIN_BARRIER_MM

RAMP_Q = 3.0
"""q of the RAMP interpolation of the barrier share (module doc)."""
W_SKIN = 0.1
"""Weight w_s of J_skin (module doc)."""
HOLD_FACTOR = 2.0
"""The design's barrier slowness is capped where a barrier `MIN_BARRIER_MM` thick holds this many horizons T."""


def hold_slowness(total_time_mm: float) -> float:
    """The largest barrier slowness a design needs: a barrier of `MIN_BARRIER_MM` then holds for `HOLD_FACTOR` T."""
    return HOLD_FACTOR * total_time_mm / MIN_BARRIER_MM


def design_slowness(barrier_speed: float, total_time_mm: float) -> float:
    """k_d, the barrier slowness the optimiser sees: 1 / s capped at `hold_slowness` (s = 0: the cap)."""
    cap = hold_slowness(total_time_mm)
    return cap if barrier_speed == 0.0 else min(1.0 / barrier_speed, cap)


def ramp(b: np.ndarray, q: float = RAMP_Q) -> tuple[np.ndarray, np.ndarray]:
    """w(b) = b / (1 + q (1 - b)) and dw/db."""
    den = 1.0 + q * (1.0 - b)
    return b / den, (1.0 + q) / (den * den)


def composite_slowness(phi: np.ndarray, f: np.ndarray, k: float, q: float = RAMP_Q
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n(phi, f) of the module doc and its partial derivatives dn/dphi, dn/df."""
    w, dw = ramp(1.0 - f, q)
    m = 1.0 + (k - 1.0) * w
    return phi * m + (1.0 - phi) * N_MIN, m - N_MIN, -phi * (k - 1.0) * dw


@dataclass(frozen=True)
class CompositeRelease:
    """The drug's release of a (phi, f) composite on the simulation grid and what its gradient needs."""

    released_mm3: np.ndarray
    u_mm: np.ndarray
    n: np.ndarray
    weight: np.ndarray
    marching: object
    dtau_mm: float
    scale: float


def composite_release(n: np.ndarray, drug: np.ndarray, dx_mm: float, mirror: tuple[bool, ...], total_time_mm: float,
                      samples: int) -> CompositeRelease:
    """Eq. (5) on the slowness ``n``, then eq. (7) weighted by the drug density (full object, mirrors included)."""
    marching = march(n, dx_mm, mirror)
    u = np.array(marching.interior(marching.u_pad))
    dtau = total_time_mm / (samples - 1)
    scale = dx_mm ** 3 * 2 ** sum(mirror)
    curve = ramp_release(u.ravel(), (n * dx_mm).ravel(), (drug * scale).ravel(), dtau, samples)
    return CompositeRelease(curve, u, n, drug, marching, dtau, scale)


def composite_gradient(release: CompositeRelease, dj_dc: np.ndarray, dx_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """dJ/dn and dJ/d(drug density) from dJ/dC (eqs. 7, 6 and the adjoint sweep, eq. 10)."""
    n, shape = release.n, release.n.shape
    u_bar, length_bar, weight_bar = ramp_release_vjp(release.u_mm.ravel(), (n * dx_mm).ravel(),
                                                     (release.weight * release.scale).ravel(), release.dtau_mm, dj_dc)
    n_bar = march_adjoint(release.marching, u_bar.reshape(shape)) + length_bar.reshape(shape) * dx_mm
    return n_bar, weight_bar.reshape(shape) * release.scale


def skin_term(drug: np.ndarray, barrier: np.ndarray, dx_mm: float, mirror: tuple[bool, ...], volume_vox: float
              ) -> tuple[float, np.ndarray, np.ndarray]:
    """J_skin of the module doc and its gradient with respect to the drug and the barrier density."""
    marching = march(barrier + (1.0 - barrier) * N_MIN, dx_mm, mirror)
    t = np.array(marching.interior(marching.u_pad)) / MIN_BARRIER_MM
    inside = t < 1.0
    g = np.where(inside, t * (1.0 - t), 0.0)
    dg = np.where(inside, 1.0 - 2.0 * t, 0.0) / MIN_BARRIER_MM
    value = float(np.sum(drug * g)) / volume_vox
    n_bar = march_adjoint(marching, drug * dg / volume_vox)
    return value, g / volume_vox, n_bar * (1.0 - N_MIN)


@dataclass(frozen=True)
class Fields:
    """One evaluation's fields on the simulation grid: material phi, drug share f, and the drug's curve."""

    phi: np.ndarray
    f: np.ndarray
    released_mm3: np.ndarray


class TwoMaterialObjective:
    """J and dJ/dx of the module doc for variables ``x = (phi_hat, f_hat)`` stacked on a leading axis.

    Parameters
    ----------
    space : design.inverse.twomaterial_problem.TwoMaterialSpace
        Variables -> simulation grid (with any fixed barrier caps).
    target_mm3 : (K,) ndarray of float
        C* on the tau grid 0..T.
    total_time_mm : float
    radius_vox : float
        Smoothing radius of both fields, voxels.
    slowness : float
        k_d (`design_slowness`).
    beta : float
        Projection steepness (changed by the continuation).
    w_binary : float
    w_skin : float
    """

    def __init__(self, space, target_mm3: np.ndarray, total_time_mm: float, *, radius_vox: float, slowness: float,
                 beta: float, w_binary: float, w_skin: float = W_SKIN) -> None:
        self.space = space
        self.target = np.asarray(target_mm3, float)
        if not self.target[-1] > 0:
            raise DesignError("the target releases nothing")
        self.total_time_mm = float(total_time_mm)
        self.filter = SmoothingFilter(space.var_shape, radius_vox, space.var_mirror)
        self.slowness = float(slowness)
        self.beta = float(beta)
        self.w_binary = float(w_binary)
        self.w_skin = float(w_skin)
        self.volume_vox = self.target[-1] / (space.dx_mm ** 3 * 2 ** sum(space.mirror))

    @property
    def x_shape(self) -> tuple[int, ...]:
        return (2,) + tuple(self.space.var_shape)

    def evaluate(self, x: np.ndarray) -> tuple[float, np.ndarray, dict[str, float], Fields]:
        """J, dJ/dx (shape `x_shape`), the terms and the fields of variables ``x`` in [0, 1]."""
        space = self.space
        smooth = [self.filter.apply(x[0]), self.filter.apply(x[1])]
        phi_v, f_v = (project(s, self.beta) for s in smooth)
        phi, f = space.to_grid(phi_v), space.drug_share(f_v)
        n, dn_dphi, dn_df = composite_slowness(phi, f, self.slowness)
        drug = phi * f
        release = composite_release(n, drug, space.dx_mm, space.mirror, self.total_time_mm, self.target.size)
        final = self.target[-1]
        resid = (release.released_mm3 - self.target) / final
        dtau_t = release.dtau_mm / self.total_time_mm
        j_fit = float(np.sum(resid ** 2) * dtau_t)
        n_bar, drug_bar = composite_gradient(release, 2.0 * resid * dtau_t / final, space.dx_mm)
        size = phi.size
        j_bin = float(np.sum(phi * (1.0 - phi) + phi * f * (1.0 - f)) / size)
        j_skin, skin_d, skin_b = skin_term(drug, phi * (1.0 - f), space.dx_mm, space.mirror, self.volume_vox)
        drug_bar = drug_bar + self.w_skin * skin_d
        barrier_bar = self.w_skin * skin_b
        g_phi = (n_bar * dn_dphi + drug_bar * f + barrier_bar * (1.0 - f)
                 + self.w_binary * ((1.0 - 2.0 * phi) + f * (1.0 - f)) / size)
        g_f = n_bar * dn_df + (drug_bar - barrier_bar) * phi + self.w_binary * phi * (1.0 - 2.0 * f) / size
        grad = np.stack([self.filter.adjoint(project_adjoint(smooth[0], self.beta, space.to_grid_adjoint(g_phi))),
                         self.filter.adjoint(project_adjoint(smooth[1], self.beta, space.drug_share_adjoint(g_f)))])
        value = j_fit + self.w_binary * j_bin + self.w_skin * j_skin
        terms = {"J": value, "J_fit": j_fit, "J_binary": j_bin, "J_skin": j_skin,
                 "rel_rmse": float(np.sqrt(np.mean(resid ** 2)))}
        return value, grad, terms, Fields(phi, f, release.released_mm3)
