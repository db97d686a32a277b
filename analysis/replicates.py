"""Replicate dissolution units: percent released of n units at common time points, with the mean, SD and CV
per time point that the regulators' f2 rules are stated in.

A dissolution test of a product runs 6 or 12 units (tablets, capsules, printed objects) and samples every
vessel at the same times; :class:`ReplicateSet` holds one product's units as a matrix. The statistics of
:mod:`analysis.regulatory`, :mod:`analysis.bootstrap` and :mod:`analysis.msd` take two such sets.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from analysis.errors import AnalysisError

TIME_UNITS_MIN = {"s": 1.0 / 60.0, "min": 1.0, "h": 60.0}
"""Minutes per time unit: the regulators' CV rules name their early points in minutes."""


@dataclass(frozen=True, eq=False)
class ReplicateSet:
    """Percent released of replicate units at common time points.

    Attributes
    ----------
    times : (T,) ndarray of float
        Strictly increasing sampling times, in ``time_unit``; time zero is allowed and never used by f2.
    units : (n, T) ndarray of float, %
        Row i is unit i's percent released (of its weighed mass or label claim) at ``times``.
    time_unit : {"s", "min", "h"}
    label : str
        Named in messages (e.g. "test", "reference").
    unit_names : tuple of str
        One name per unit (file or column), default ``unit 1``, ``unit 2``, ...

    Raises
    ------
    AnalysisError
        Shapes, a non-finite value, times that do not increase, an unknown time unit.
    """

    times: np.ndarray
    units: np.ndarray
    time_unit: str = "min"
    label: str = "set"
    unit_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t = np.array(self.times, dtype=float)
        u = np.array(self.units, dtype=float)
        if u.ndim == 1:
            u = u[None, :]
        name = self.label
        if self.time_unit not in TIME_UNITS_MIN:
            raise AnalysisError(f"{name}: time unit {self.time_unit!r}; expected one of {', '.join(TIME_UNITS_MIN)}")
        if t.ndim != 1 or u.ndim != 2 or u.shape[1] != t.size:
            raise AnalysisError(f"{name}: times {t.shape} and units {u.shape} must be (T,) and (n, T)")
        if t.size < 1 or u.shape[0] < 1:
            raise AnalysisError(f"{name}: no time points or no units")
        for what, values in (("time", t), ("percent released", u)):
            bad = np.argwhere(~np.isfinite(values))
            if bad.size:
                where = tuple(int(i) for i in bad[0])
                raise AnalysisError(f"{name}: {what} at index {where} = {values[where]} is not a finite number")
        steps = np.flatnonzero(np.diff(t) <= 0)
        if steps.size:
            i = int(steps[0]) + 1
            raise AnalysisError(f"{name}: time {t[i]:g} {self.time_unit} (point {i}) does not increase after "
                                f"{t[i - 1]:g}; times must increase strictly")
        names = tuple(self.unit_names) or tuple(f"unit {i + 1}" for i in range(u.shape[0]))
        if len(names) != u.shape[0]:
            raise AnalysisError(f"{name}: {len(names)} unit names for {u.shape[0]} units")
        t.flags.writeable = False
        u.flags.writeable = False
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "units", u)
        object.__setattr__(self, "unit_names", names)

    @property
    def n_units(self) -> int:
        return int(self.units.shape[0])

    @property
    def mean(self) -> np.ndarray:
        """(T,) mean percent released per time point."""
        return self.units.mean(axis=0)

    @property
    def sd(self) -> np.ndarray:
        """(T,) sample standard deviation (n - 1) per time point; 0 for a single unit."""
        if self.n_units < 2:
            return np.zeros(self.times.size)
        return self.units.std(axis=0, ddof=1)

    @property
    def cv_pct(self) -> np.ndarray:
        """(T,) coefficient of variation, 100 SD / mean, %; 0 where the mean is 0 (as bootf2 does)."""
        mean = self.mean
        with np.errstate(divide="ignore", invalid="ignore"):
            cv = 100.0 * self.sd / mean
        return np.where(np.isfinite(cv), cv, 0.0)

    @property
    def times_min(self) -> np.ndarray:
        """(T,) the times in minutes."""
        return self.times * TIME_UNITS_MIN[self.time_unit]

    def table(self) -> list[dict]:
        """One row per time point: time, mean, SD, CV (the replicate table of a report)."""
        return [{"time": float(t), "mean_pct": float(m), "sd_pct": float(s), "cv_pct": float(c)}
                for t, m, s, c in zip(self.times, self.mean, self.sd, self.cv_pct)]

    def without_time_zero(self) -> ReplicateSet:
        """The set without points at time zero or before (f2 never uses them)."""
        keep = self.times > 0
        return ReplicateSet(self.times[keep], self.units[:, keep], self.time_unit, self.label, self.unit_names)


def check_same_times(test: ReplicateSet, reference: ReplicateSet) -> None:
    """Refuse two sets that are not sampled at the same times in the same unit (the guidelines' first rule)."""
    if test.time_unit != reference.time_unit:
        raise AnalysisError(f"{test.label} is timed in {test.time_unit} but {reference.label} in "
                            f"{reference.time_unit}; give both in one unit")
    if test.times.shape != reference.times.shape or not np.allclose(test.times, reference.times, rtol=1e-9, atol=0):
        raise AnalysisError(f"{test.label} ({', '.join(f'{t:g}' for t in test.times)} {test.time_unit}) and "
                            f"{reference.label} ({', '.join(f'{t:g}' for t in reference.times)}) are not sampled at "
                            f"the same time points; f2 and the multivariate tests need the same points")


def from_columns(times: Sequence[float], columns: Sequence[Sequence[float]], *, time_unit: str = "min",
                 label: str = "set", unit_names: Sequence[str] = ()) -> ReplicateSet:
    """A set from one column per unit (as bootf2 and DDSolver lay out their sheets: time, unit01, unit02, ...)."""
    return ReplicateSet(np.asarray(times, dtype=float), np.asarray(columns, dtype=float), time_unit, label,
                        tuple(unit_names))
