"""Which shapes to print to calibrate print physics: ``sfr calibrate-sim --plan`` (a small D-optimal design).

Each candidate print (the shipped samples, and generated shapes that tell the build direction and narrow
channels apart: a flat slab, a tall column, a channelled slab) is simulated at nominal print physics and with
each parameter moved a little; its mass-normalised release C(t) = V(t / s) / V_final, sampled at
``points`` independent times over its dissolution, gives a sensitivity Jacobian J (points x parameters,
central differences) to the time scale (log s, always fitted) and to the physics parameters asked for.
With a calibration error of ``noise`` (fraction of the weighed mass) at each independent point, the Fisher
information of a set of prints is

    F = P + sum_prints J^T J / noise^2,

with P a weak prior (one standard deviation of 1 in log s and log anisotropy, 1 mm in offset and swelling
width) that keeps F invertible before the parameters are separable. The prints are chosen greedily: each
step adds the candidate that maximises log det F (D-optimality); the expected standard error of each
parameter is sqrt(diag(F^-1)) (the Cramer-Rao bound of the linearised fit). The calibration's error is not
white noise: the leave-one-out errors on the simulated bench are 1-4% of the mass and correlated over a
run, which ``noise`` at a few ``points`` per run stands for (defaults below).
"""
from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from analysis.physics_grid import LAG, PHYSICS_IDENTITY, PHYSICS_PARAMETERS, PHYSICS_SETS
from labapp.errors import UsageError
from labapp.records.fileio import atomic_write
from labapp.records.outpaths import FolderKind, check_out

PLAN_PRINTS = 4
"""Prints proposed by default."""
PLAN_NOISE = 0.01
"""Default calibration error per independent point, fraction of the weighed mass (the simulated bench's
leave-one-out errors are 1-4%)."""
PLAN_POINTS = 10
"""Default independent points per run: a calibration error correlated over a tenth of the run."""
PLAN_RESOLUTION = 32
"""Voxels along each candidate's longest side for the sensitivity simulations."""
PLAN_NOMINAL = {"anisotropy": 1.0, "offset_mm": 0.0, "swelling_mm": 0.5}
"""Physics at which the sensitivities are taken: the identity, except a swelling width in the middle of the
documented 0.3-0.8 mm (at zero width no channel is shut and the release does not depend on it)."""
STEPS = {"log_seconds": 0.05, "anisotropy": 0.1, "offset_mm": 0.05, "swelling_mm": 0.1, LAG: 30.0}
"""Central-difference half-steps: log s, log anisotropy, offset (mm), swelling width (mm), wetting lag (s)."""
PRIOR_SD = {"log_seconds": 1.0, "anisotropy": 1.0, "offset_mm": 1.0, "swelling_mm": 1.0, LAG: 1000.0}
"""The weak prior's standard deviation of each parameter (log s and log anisotropy; mm; the lag in s)."""
PLAN_SECONDS_PER_MM = 1500.0
"""The time scale at which the wetting lag's sensitivity is taken (the plan's clock is tau, the lag is in seconds:
C(t) = V((t - lag) / s)); the middle of the simulated bench's 1000-2400 s/mm. Its expected standard error scales
with the real time scale."""


def _flat() -> trimesh.Trimesh:
    return trimesh.creation.box((18.0, 18.0, 4.0))


def _tall() -> trimesh.Trimesh:
    return trimesh.creation.cylinder(radius=4.5, height=20.0, sections=48)


def _bar() -> trimesh.Trimesh:
    return trimesh.creation.box((22.0, 6.0, 6.0))


def _channelled() -> trimesh.Trimesh:
    """A 16 x 16 x 6 mm slab cut by three vertical slots of 0.5 mm (narrower than a swollen material keeps open)."""
    slab = trimesh.creation.box((16.0, 16.0, 6.0))
    slots = [trimesh.creation.box((0.5, 12.0, 8.0), transform=trimesh.transformations.translation_matrix((x, 0, 0)))
             for x in (-4.0, 0.0, 4.0)]
    return slab.difference(trimesh.util.concatenate(slots))


GENERATED = {"flat": (_flat, "flat slab, 18 x 18 x 4 mm: erodes mostly along the build direction"),
             "tall": (_tall, "tall column, 9 mm across, 20 mm high: erodes mostly in the plane"),
             "bar": (_bar, "bar lying down, 22 x 6 x 6 mm: erodes along the build direction and in the plane alike"),
             "channelled": (_channelled, "16 x 16 x 6 mm slab with three 0.5 mm slots: opens only if they do")}
"""Generated calibration shapes: name -> (mesh maker, description)."""


@dataclass(frozen=True)
class Candidate:
    """A print the plan may propose: its name, mesh, description and sensitivity Jacobian."""

    name: str
    mesh: trimesh.Trimesh
    description: str
    jacobian: np.ndarray
    """(points, parameters): dC/dparameter at the sample times, C the mass-normalised release."""


@dataclass(frozen=True)
class PlanStep:
    """One proposed print and the expected standard errors once it is added."""

    name: str
    description: str
    why: str
    std: dict


@dataclass(frozen=True)
class Plan:
    """The proposed prints, in order, and what they are expected to resolve."""

    parameters: tuple[str, ...]
    steps: tuple[PlanStep, ...]
    noise: float
    points: int

    @property
    def std(self) -> dict:
        """Expected standard error of each parameter with all the proposed prints."""
        return self.steps[-1].std


def plan_nominal(parameters: Sequence[str]) -> dict:
    """The physics the sensitivities are taken at: `PLAN_NOMINAL` for the parameters planned, the identity for
    the others (a swelling width not planned for shuts no channel)."""
    return {p: PLAN_NOMINAL[p] if p in parameters else PHYSICS_IDENTITY[p] for p in PHYSICS_PARAMETERS}


def _normalised(tau: np.ndarray, vol: np.ndarray, t_over_s: np.ndarray) -> np.ndarray:
    return np.interp(t_over_s, tau, vol / vol[-1], left=0.0, right=1.0)


def sensitivity(mesh: trimesh.Trimesh, parameters: Sequence[str], *, points: int = PLAN_POINTS,
                resolution: int = PLAN_RESOLUTION,
                simulate_at: Callable[[trimesh.Trimesh, dict], tuple[np.ndarray, np.ndarray]] | None = None
                ) -> np.ndarray:
    """dC/dparameter of a print's mass-normalised release at ``points`` times over its dissolution.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    parameters : sequence of str
        ``log_seconds``, names of `PHYSICS_PARAMETERS` and `analysis.physics_grid.LAG` (``wetting_lag_s``).
    points : int
        Sample times, uniform over (0, 1.1 x the nominal dissolution time].
    resolution : int
    simulate_at : callable, optional
        ``simulate_at(mesh, physics) -> (tau_mm, released_mm3)`` (default: the forward model at ``resolution``).

    Returns
    -------
    (points, len(parameters)) ndarray of float
    """
    if simulate_at is None:
        from design.files.pipeline import simulate_mesh

        def simulate_at(m, physics):
            r = simulate_mesh(m, resolution=resolution, **physics)
            return r.tau_mm, r.released_mm3

    nominal = plan_nominal(parameters)
    tau, vol = simulate_at(mesh, nominal)
    x = np.linspace(0.0, 1.1 * tau[-1], points + 1)[1:]     # t / s at the nominal time scale, mm
    columns = []
    for p in parameters:
        h = STEPS[p]
        if p == "log_seconds":   # C(t) = V(t / s): moving log s by h rescales the time axis
            up, down = _normalised(tau, vol, x * math.exp(-h)), _normalised(tau, vol, x * math.exp(h))
        elif p == LAG:   # C(t) = V((t - lag) / s): moving the lag by h shifts the time axis
            up, down = (_normalised(tau, vol, x - sign * h / PLAN_SECONDS_PER_MM) for sign in (1, -1))
        else:
            moved = []
            for sign in (1, -1):
                values = dict(nominal)
                values[p] = nominal[p] * math.exp(sign * h) if p == "anisotropy" else nominal[p] + sign * h
                moved.append(_normalised(*simulate_at(mesh, values), x))
            up, down = moved
        columns.append((up - down) / (2 * h))
    return np.column_stack(columns)


def _prior(parameters: Sequence[str]) -> np.ndarray:
    return np.diag([1.0 / PRIOR_SD[p] ** 2 for p in parameters])


def expected_std(parameters: Sequence[str], jacobians: Sequence[np.ndarray], noise: float) -> dict:
    """sqrt(diag(F^-1)) for the prints of ``jacobians`` (see the module docstring)."""
    fisher = _prior(parameters) + sum((j.T @ j for j in jacobians), np.zeros((len(parameters),) * 2)) / noise ** 2
    cov = np.linalg.inv(fisher)
    return {p: float(math.sqrt(cov[i, i])) for i, p in enumerate(parameters)}


def choose(candidates: Sequence[Candidate], parameters: Sequence[str], prints: int, noise: float,
           points: int) -> Plan:
    """Greedy D-optimal choice of ``prints`` distinct candidates (each step maximises log det F)."""
    if not 1 <= prints <= len(candidates):
        raise UsageError(f"--plan-prints {prints} must be between 1 and the {len(candidates)} candidate shapes")
    chosen: list[Candidate] = []
    steps = []
    std = expected_std(parameters, [], noise)
    for _ in range(prints):
        best, best_logdet = None, -math.inf
        for c in candidates:
            if c in chosen:
                continue
            fisher = _prior(parameters) + sum(j.jacobian.T @ j.jacobian for j in chosen + [c]) / noise ** 2
            logdet = float(np.linalg.slogdet(fisher)[1])
            if logdet > best_logdet:
                best, best_logdet = c, logdet
        chosen.append(best)
        new = expected_std(parameters, [c.jacobian for c in chosen], noise)
        gain = max(parameters, key=lambda p: std[p] / new[p])
        why = (f"{best.description}; cuts the std of {gain} {std[gain]:.3g} -> {new[gain]:.3g}"
               + ("" if len(chosen) > 1 else " (with the prior alone before it)"))
        steps.append(PlanStep(best.name, best.description, why, new))
        std = new
    return Plan(tuple(parameters), tuple(steps), noise, points)


def _describe_sample(mesh: trimesh.Trimesh, name: str) -> str:
    x, y, z = mesh.extents
    return f"shipped sample '{name}', {x:.0f} x {y:.0f} x {z:.0f} mm"


def candidates(points: int = PLAN_POINTS, resolution: int = PLAN_RESOLUTION, parameters: Sequence[str] = (),
               progress: Callable[[str], None] = lambda text: None) -> list[Candidate]:
    """The shipped samples and the generated shapes with their Jacobians."""
    from design.geometry.shapes import SAMPLE_SHAPES, sample_shape

    meshes = [(f"sample:{n}", sample_shape(n), None) for n in SAMPLE_SHAPES]
    meshes += [(n, make(), text) for n, (make, text) in GENERATED.items()]
    out = []
    for name, mesh, text in meshes:
        progress(f"sensitivities of {name} ...")
        out.append(Candidate(name, mesh, text or _describe_sample(mesh, name.split(":", 1)[1]),
                             sensitivity(mesh, parameters, points=points, resolution=resolution)))
    return out


def plan_prints(physics: str, out_dir: str | Path | None = None, *, prints: int = PLAN_PRINTS,
                noise: float = PLAN_NOISE, points: int = PLAN_POINTS, resolution: int = PLAN_RESOLUTION,
                progress: Callable[[str], None] = lambda text: None) -> Plan:
    """Propose calibration prints that separate the print physics of ``physics`` (``sfr calibrate-sim --plan``).

    Parameters
    ----------
    physics : str
        A ``--physics`` set (``anisotropy``, ``offset``, ``all``, ...; ``auto`` plans for ``all``).
    out_dir : str or Path, optional
        Where to write ``plan.csv``, ``plan.json`` and the proposed generated shapes' STL files.
    prints, noise, points, resolution
        See the module docstring.

    Raises
    ------
    UsageError
        An unknown physics set, a noise or count out of range, an ``out_dir`` that is another command's folder.
    """
    name = "all" if physics == "auto" else physics
    if name not in PHYSICS_SETS:
        raise UsageError(f"--physics {physics!r} is not one of {', '.join(PHYSICS_SETS)} or auto")
    if not (math.isfinite(noise) and 0 < noise < 1):
        raise UsageError(f"--plan-noise {noise!r} must be a fraction of the mass between 0 and 1")
    if not 2 <= points <= 1000:
        raise UsageError(f"--plan-points {points!r} must be between 2 and 1000")
    from design.geometry.shapes import SAMPLE_SHAPES

    if not 1 <= prints <= len(SAMPLE_SHAPES) + len(GENERATED):
        raise UsageError(f"--plan-prints {prints} must be between 1 and the {len(SAMPLE_SHAPES) + len(GENERATED)} "
                         "candidate shapes")
    parameters = ("log_seconds",) + tuple(PHYSICS_SETS[name])
    if out_dir is not None:
        out_dir = check_out(out_dir, FolderKind.SIMCAL, [], replace=False)
    plan = choose(candidates(points, resolution, parameters, progress), parameters, prints, noise, points)
    if out_dir is not None:
        _write(plan, Path(out_dir), physics)
    return plan


def _write(plan: Plan, out_dir: Path, physics: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for k, step in enumerate(plan.steps, start=1):
        mesh = step.name
        if step.name in GENERATED:
            mesh = f"{step.name}.stl"
            GENERATED[step.name][0]().export(out_dir / mesh)
        rows.append({"order": k, "shape": step.name, "mesh": mesh, "why": step.why,
                     **{f"std_{p}": f"{v:.4g}" for p, v in step.std.items()}})
    with open(out_dir / "plan.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    doc = {"physics": physics, "parameters": list(plan.parameters), "noise": plan.noise, "points": plan.points,
           "nominal": plan_nominal(plan.parameters),
           "expected_std": plan.std, "prints": rows,
           "note": "expected std: Cramer-Rao bound of the linearised fit (log s and log anisotropy are relative)"}
    atomic_write(out_dir / "plan.json", (json.dumps(doc, indent=2) + "\n").encode())
