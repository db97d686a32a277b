"""The inverse-design objective of eq. (4) and its gradient with respect to the design variables.

``J = J_fit + w_b J_binary + w_f J_fab + w_r J_rate + w_c J_conn + w_ch J_chan`` with
``rho = project(smooth(rho_hat, r), beta)``; J_rate (`design.inverse.rate.rate_fit`) is an optional rate-fit term
beyond the paper (w_r = 0 gives eq. 4), and so is J_conn (`design.fabrication.connectivity`), the penalty on material
that does not connect to the design's symmetry centre (w_c = 0 allows pieces, as in the paper), and J_chan
(`design.fabrication.channels`), the void of open channels narrower than a minimum width (the print's swelling
width), measured by a smooth closing of the nominal design (w_ch = 0: no minimum width, as in the paper).

The chain is: variables -> smoothing filter -> projection -> design-space map (replication for
extruded designs) -> fast-marching release (eqs. 5-7) -> J; the gradient runs the chain backwards
with the exact adjoint of every stage.

Robust formulation (optional, beyond the paper; after Wang, Lazarov and Sigmund 2011): with
``robust_eta = d > 0`` the designs projected at thresholds 1/2 - d (dilated) and 1/2 + d (eroded)
are simulated too, and J_rate becomes the mean of the nominal design's J_rate and the two others'
J_shape (`design.inverse.rate.rate_shape_fit`: the target's rate profile at their own level, since they
hold less and more material than the target). J_fit, J_binary and J_fab stay on the nominal design.
A design whose release relies on thin grey layers (which the printed solid's contour deletes or fills)
then pays for it, because those layers vanish in the eroded design. Three simulations per evaluation;
needs w_r > 0.

Units. The terms are evaluated after rescaling lengths so that the target's final release equals
``REFERENCE_MASS_MM3`` (1326 mm^3: the paper's ~1.75 g prints at 1.32 g/cm^3, sections 4.1, 5.1).
Equation (4) mixes mm^6 (J_fit) and mm^3 (J_binary), so the balance between the terms depends on
object size; rescaling to the paper's size lets its weights (Tables 1-2) carry over to any domain.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from design.errors import DesignError
from design.fabrication.channels import NarrowVoids
from design.fabrication.connectivity import TAIL_SLOPE, Connectivity, block_edge
from design.forward.fmm import MarchBuffers
from design.forward.simulator import Release, release_gradient, simulate
from design.geometry.shapes import PRINT_MASS_G
from design.inverse.filters import SmoothingFilter, project, project_adjoint, project_inverse
from design.inverse.rate import rate_fit, rate_shape_fit, release_duration
from design.inverse.spaces import DesignSpace
from design.material import PRINT_DENSITY_G_PER_CM3

REFERENCE_MASS_MM3 = PRINT_MASS_G * 1000.0 / PRINT_DENSITY_G_PER_CM3
"""Final release the objective is normalised to, mm^3 (1.75 g at 1.32 g/cm^3)."""

START_OUTSIDE = 0.02
"""Variable value outside a compact start region (`DesignObjective.uniform_start`)."""


@dataclass(frozen=True)
class Evaluation:
    """One evaluation of the objective.

    Attributes
    ----------
    value : float
        J of eq. (4) in the rescaled units.
    terms : dict of str to float
        ``J_fit``, ``J_binary``, ``J_fab``, ``J_rate``, ``J_conn``, ``J_chan`` (unweighted) and ``grad_norm``.
    grad : ndarray of float, variable shape
        dJ/d rho_hat.
    rho : ndarray of float, reduced grid shape
        The filtered density that was simulated.
    release : Release
        Its gradient is unavailable once the objective has been evaluated again (shared buffers).
    """

    value: float
    terms: dict[str, float]
    grad: np.ndarray
    rho: np.ndarray
    release: Release


class DesignObjective:
    """J of eq. (4) for one design space and one target curve.

    Parameters
    ----------
    space : DesignSpace
    target_mm3 : (K,) ndarray of float, mm^3
        Target cumulative release C* on the grid ``tau_k = k T / (K - 1)``.
    total_time_mm : float
        Simulated duration T, mm.
    radius_vox : float
        Smoothing radius r, voxels.
    beta : float
        Projection steepness.
    w_binary, w_fab : float
        Weights of J_binary and J_fab.
    w_rate : float
        Weight of the rate-fit term J_rate (0 = eq. 4 as in the paper).
    rate_lag : int or None
        Finite-difference lag of J_rate in tau samples; None = one voxel edge (``dx / dtau``),
        the shortest span over which a voxel release is free of layer ripple.
    robust_eta : float
        Threshold offset d of the robust formulation (module doc), in [0, 0.4]; 0 = off.
    rate_span : (float, float)
        J_rate counts the rates between the times the target reaches these fractions of its final
        release (both ends of each lag inside); (0, 1) = the whole curve.
    w_conn : float
        Weight of the connectivity penalty J_conn (0 = off), evaluated on the nominal design.
    conn_coarsen : int or None
        Block edge of J_conn's distance grid, voxels; None = `design.fabrication.connectivity.block_edge`.
    conn_planes : bool
        J_conn's plane term (`design.fabrication.connectivity.Connectivity`); False = the core term alone.
    conn_tail : float
        Slope of J_conn's tail (`design.fabrication.connectivity.TAIL_SLOPE`); 0 = no tail.
    anisotropy : float
        Erosion speed along z over the in-plane speed in the forward model (print physics; 1 = isotropic).
    swelling_mm : float
        Channels narrower than this are shut in the forward model (print physics, `design.forward.swelling`);
        the plug is held fixed by the gradient.
    w_channel : float
        Weight of J_chan (`design.fabrication.channels`; 0 = off), evaluated on the nominal design's grid in the
        rescaled units of J_binary (mm^3 of the whole object).
    channel_mm : float or None
        J_chan's minimum open channel width, mm; None = ``swelling_mm``. Needs a width > 0 when w_channel > 0.
    """

    def __init__(self, space: DesignSpace, target_mm3: np.ndarray, total_time_mm: float, *,
                 radius_vox: float, beta: float, w_binary: float, w_fab: float = 0.0, w_rate: float = 0.0,
                 rate_lag: int | None = None, robust_eta: float = 0.0,
                 rate_span: tuple[float, float] = (0.0, 1.0), w_conn: float = 0.0,
                 conn_coarsen: int | None = None, conn_planes: bool = True,
                 conn_tail: float = TAIL_SLOPE, anisotropy: float = 1.0, swelling_mm: float = 0.0,
                 w_channel: float = 0.0, channel_mm: float | None = None) -> None:
        target = np.asarray(target_mm3, dtype=float)
        if target.ndim != 1 or target.size < 3 or not target[-1] > 0:
            raise DesignError(f"target must be a 1D curve with >= 3 samples and a positive end, got {target.shape}")
        if not beta > 0 or w_binary < 0 or w_fab < 0 or w_rate < 0:
            raise DesignError(f"need beta > 0, w_binary >= 0, w_fab >= 0, w_rate >= 0; got {beta}, {w_binary}, "
                              f"{w_fab}, {w_rate}")
        if not 0.0 <= robust_eta <= 0.4:
            raise DesignError(f"robust_eta must be in [0, 0.4], got {robust_eta}")
        if robust_eta > 0 and not w_rate > 0:
            raise DesignError("the robust formulation compares release rates: it needs w_rate > 0")
        if not 0.0 <= rate_span[0] < rate_span[1] <= 1.0:
            raise DesignError(f"rate_span must be two fractions 0 <= lo < hi <= 1, got {rate_span}")
        if w_conn < 0:
            raise DesignError(f"w_conn must be >= 0, got {w_conn}")
        width_mm = float(swelling_mm if channel_mm is None else channel_mm)
        if not (np.isfinite(w_channel) and w_channel >= 0):
            raise DesignError(f"w_channel must be a finite number >= 0, got {w_channel}")
        if w_channel > 0 and not width_mm > 0:
            raise DesignError(f"w_channel = {w_channel} needs a minimum channel width > 0 mm, got {width_mm}")
        if w_fab > 0 and space.fab_term is None:
            raise DesignError(f"w_fab = {w_fab} but design space {space.name!r} has no fabrication term")
        self.space = space
        self.physics = {"anisotropy": float(anisotropy), "swelling_mm": float(swelling_mm)}
        self.target_mm3 = target
        self.total_time_mm = float(total_time_mm)
        self.beta = float(beta)
        self.w_binary = float(w_binary)
        self.w_fab = float(w_fab)
        self.filter = SmoothingFilter(space.var_shape, float(radius_vox), space.var_mirror)
        self.scale = (REFERENCE_MASS_MM3 / target[-1]) ** (1.0 / 3.0)  # length rescaling, see module doc
        self.dtau_mm = self.total_time_mm / (target.size - 1)
        self.w_rate = float(w_rate)
        lag = max(1, int(round(space.dx_mm / self.dtau_mm))) if rate_lag is None else int(rate_lag)
        if not 1 <= lag < target.size:
            raise DesignError(f"rate lag must be in [1, {target.size - 1}] samples, got {lag}")
        self.rate_lag = lag
        # rates r_k = (C_{k+L} - C_k) / (L dtau) with tau_k at or after the lo point, tau_{k+L} at or before hi
        first = int(np.argmax(target >= rate_span[0] * target[-1]))
        last = target.size - 1 if rate_span[1] >= 1.0 else int(np.argmax(target >= rate_span[1] * target[-1]))
        self.rate_samples = (first, max(first + 1, last - lag + 1))
        tau = np.linspace(0.0, self.total_time_mm, target.size)
        self.rate_time_scale_mm = release_duration(tau, target)  # t_s of J_rate
        self.thresholds = (0.5,) if robust_eta == 0 else (0.5 - robust_eta, 0.5, 0.5 + robust_eta)
        self._buffers = [MarchBuffers(space.grid_shape) for _ in self.thresholds]  # reused by every evaluation
        if self.w_fab > 0:  # J_fab is divided by its value at the start design (design.fabrication.ico)
            space.fab_term.normalise_at(self.density(self.uniform_start()))
        self.w_conn = float(w_conn)
        coarsen = block_edge(radius_vox, len(space.var_shape)) if conn_coarsen is None else int(conn_coarsen)
        self.connectivity = (Connectivity(space.var_shape, space.var_mirror, space.dx_mm, coarsen,
                                          planes=conn_planes, tail_slope=conn_tail)
                             if self.w_conn > 0 else None)
        self.w_channel = float(w_channel)
        self.channels = (NarrowVoids(space.grid_shape, space.dx_mm, width_mm, space.mirror)
                         if self.w_channel > 0 else None)

    def density(self, x: np.ndarray) -> np.ndarray:
        """The reduced simulation density ``rho`` of variables ``x`` (eq. 4 filter chain)."""
        return self.space.to_grid(project(self.filter.apply(x), self.beta))

    def uniform_start(self, region: np.ndarray | None = None) -> np.ndarray:
        """Uniform variables whose filtered mass is the target's final release (section 5.2).

        The normalised smoothing filter keeps a uniform field uniform, so the constant is the
        inverse projection of the required uniform density.

        Parameters
        ----------
        region : ndarray of bool, variable shape, optional
            Put the material only here (a compact start, `design.inverse.problem.start_region`); outside, the
            variables get `START_OUTSIDE` so that the cosine bound map still has a gradient there.
            The filter blurs the region's edge, so the start's mass is then close to, not exactly,
            the target's. None = the whole domain.
        """
        space = self.space
        per_var = float(np.prod(space.grid_shape)) / float(np.prod(space.var_shape))
        cells = (float(np.prod(space.var_shape)) if region is None else float(np.count_nonzero(region))) * per_var
        rho = self.target_mm3[-1] / (cells * space.dx_mm ** 3 * space.multiplicity)
        if rho >= 1.0:
            where = "design domain" if region is None else "start region"
            raise DesignError(f"target releases {self.target_mm3[-1]:.4g} mm^3, more than the {where} holds "
                              f"({cells * space.dx_mm ** 3 * space.multiplicity:.4g} mm^3)")
        if region is None:
            return np.full(space.var_shape, project_inverse(rho, self.beta))
        return np.where(region, project_inverse(rho, self.beta), START_OUTSIDE)

    def evaluate(self, x: np.ndarray) -> Evaluation:
        """J and dJ/dx at variables ``x`` (variable shape, values in [0, 1])."""
        space = self.space
        smoothed = self.filter.apply(x)
        share = 1.0 / len(self.thresholds)  # J_rate is the mean over the simulated designs
        j_rate = j_bin = j_fab = j_conn = j_chan = fab_seconds = 0.0
        grad_var = np.zeros(space.var_shape)
        for eta, buffers in zip(self.thresholds, self._buffers):
            rho_var = project(smoothed, self.beta, eta)
            rho = space.to_grid(rho_var)
            # J_binary = sum_i rho_i (1 - rho_i) dx^3 over the full object (section 3.4)
            cell = (space.dx_mm * self.scale) ** 3 * space.multiplicity
            pending = None  # J_conn's distance solves run in worker threads while the release is solved
            if eta == 0.5 and self.connectivity is not None:  # one variable voxel stands for its whole extruded column
                pending = self.connectivity.submit(rho_var, cell * rho.size / rho_var.size)
            release = simulate(rho, space.dx_mm, mirror=space.mirror, total_time_mm=self.total_time_mm,
                               dtau_mm=self.dtau_mm, buffers=buffers, **self.physics)
            if eta != 0.5:  # an eroded or dilated design of the robust formulation
                rate, d_curve = self._shape_terms(release, share)
                j_rate += share * rate
                grad_var += project_adjoint(smoothed, self.beta, space.to_grid_adjoint(
                    release_gradient(release, d_curve)), eta)
                continue
            j_fit, rate, d_curve = self._curve_terms(release, share)
            j_rate += share * rate
            grad_rho = release_gradient(release, d_curve)
            nominal_rho, nominal_release = rho, release
            j_bin = float(np.sum(rho * (1.0 - rho)) * cell)
            grad_rho += self.w_binary * (1.0 - 2.0 * rho) * cell
            if self.w_fab > 0:
                t_fab = time.perf_counter()
                j_fab, g_fab = space.fab_term(rho)
                fab_seconds = time.perf_counter() - t_fab
                grad_rho += self.w_fab * g_fab
            if self.channels is not None:
                j_chan, g_chan = self.channels(rho, cell)
                grad_rho += self.w_channel * g_chan
            g_proj = space.to_grid_adjoint(grad_rho)
            if pending is not None:
                j_conn, g_conn = pending.result()
                g_proj = g_proj + self.w_conn * g_conn
            grad_var += project_adjoint(smoothed, self.beta, g_proj, eta)
        grad = self.filter.adjoint(grad_var)
        value = (j_fit + self.w_binary * j_bin + self.w_fab * j_fab + self.w_rate * j_rate + self.w_conn * j_conn
                 + self.w_channel * j_chan)
        terms = {"J": value, "J_fit": j_fit, "J_binary": j_bin, "J_fab": float(j_fab), "J_rate": j_rate,
                 "J_conn": j_conn, "J_chan": j_chan, "grad_norm": float(np.linalg.norm(grad)), "fab_seconds": fab_seconds}
        return Evaluation(value, terms, grad, nominal_rho, nominal_release)

    def _curve_terms(self, release: Release, rate_share: float) -> tuple[float, float, np.ndarray]:
        """J_fit, J_rate (unweighted, rescaled units) of one curve, and d(J_fit + w_r rate_share J_rate)/dC."""
        if release.released_mm3.shape != self.target_mm3.shape:
            raise DesignError(f"simulated curve has {release.released_mm3.size} samples, target has "
                              f"{self.target_mm3.size}")
        s3 = self.scale ** 3
        # J_fit, eq. (4) with the rectangle rule of section 3.4: (1/T) sum_k (C_k - C*_k)^2 dtau
        resid = (release.released_mm3 - self.target_mm3) * s3
        j_fit = float(np.sum(resid ** 2) * self.dtau_mm / self.total_time_mm)
        d_curve = 2.0 * resid * s3 * self.dtau_mm / self.total_time_mm
        j_rate = 0.0
        if self.w_rate > 0:  # J_rate in the rescaled units: C -> s^3 C, tau -> s tau
            j_rate, g_rate = rate_fit(release.released_mm3 * s3, self.target_mm3 * s3, self.dtau_mm * self.scale,
                                      self.rate_lag, self.rate_time_scale_mm * self.scale, self.rate_samples)
            d_curve = d_curve + self.w_rate * rate_share * g_rate * s3
        return j_fit, j_rate, d_curve

    def _shape_terms(self, release: Release, rate_share: float) -> tuple[float, np.ndarray]:
        """J_shape (unweighted, rescaled units) of one curve, and d(w_r rate_share J_shape)/dC."""
        s3 = self.scale ** 3
        j_shape, g_shape = rate_shape_fit(release.released_mm3 * s3, self.target_mm3 * s3, self.dtau_mm * self.scale,
                                          self.rate_lag, self.rate_time_scale_mm * self.scale, self.rate_samples)
        return j_shape, self.w_rate * rate_share * g_shape * s3


def rel_rmse(curve_mm3: np.ndarray, target_mm3: np.ndarray) -> float:
    """RMS deviation over the tau grid divided by the target's final value (the accuracy metric)."""
    return float(np.sqrt(np.mean((np.asarray(curve_mm3) - target_mm3) ** 2)) / target_mm3[-1])
