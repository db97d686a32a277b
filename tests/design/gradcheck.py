"""The finite-difference check of a design objective's gradient, shared by the objective tests."""
import numpy as np

FD_STEP = 1e-6
FD_TOLERANCE = 1e-5
"""J ~ 1e5 in double precision: the central difference's round-off is ~1e-16 J / h ~ 1e-5 and its
truncation O(h^2); the fast-marching upwind choice is locally constant, so 1e-5 of the largest gradient
entry is ample."""


def assert_gradient_matches_fd(objective, x: np.ndarray, grad: np.ndarray, rng: np.random.Generator,
                               entries: int) -> None:
    """Central differences of ``objective.evaluate(x).value`` at ``entries`` random entries of ``x`` agree with
    ``grad`` to `FD_TOLERANCE` of its largest entry."""
    scale = np.abs(grad).max()
    for _ in range(entries):
        idx = tuple(int(rng.integers(0, n)) for n in x.shape)
        xp, xm = x.copy(), x.copy()
        xp[idx] += FD_STEP
        xm[idx] -= FD_STEP
        fd = (objective.evaluate(xp).value - objective.evaluate(xm).value) / (2 * FD_STEP)
        assert abs(grad[idx] - fd) <= FD_TOLERANCE * scale, (idx, grad[idx], fd)
