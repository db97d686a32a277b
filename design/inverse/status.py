"""How a design run ended: the ``status`` of `design.files.rundir.DesignResult` and of ``summary.json``."""
from __future__ import annotations

import enum


class DesignStatus(enum.StrEnum):
    """Why a design run's optimisation ended. A `str` (JSON and comparisons read the value)."""

    CONVERGED = "converged"
    """The optimiser's own criteria were met (or its restarts made no further progress)."""
    MAX_ITER = "max_iter"
    """The evaluation limit (`DesignConfig.max_iter`) was reached."""
    STALLED = "stalled"
    """The line search found no acceptable step and the restarts were exhausted."""
    STOPPED = "stopped"
    """``should_stop`` asked the run to stop; it resumes."""
    INTERRUPTED = "interrupted"
    """Ctrl-C; the run resumes."""

    @property
    def text(self) -> str:
        """The status in words for the summary's first line: a stalled line search is where L-BFGS converges to
        numerical precision (no step lowers J), said so rather than as a failure."""
        return "converged (no step lowers J further)" if self is DesignStatus.STALLED else self.value

    @property
    def finished(self) -> bool:
        """Whether the run is over (converged, max_iter or stalled), rather than stopped or interrupted."""
        return self in FINISHED


FINISHED = (DesignStatus.CONVERGED, DesignStatus.MAX_ITER, DesignStatus.STALLED)
"""The statuses that finish a design run; "stopped" and "interrupted" runs resume."""
