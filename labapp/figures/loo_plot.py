"""The simulation calibration's leave-one-out figure: each shape's measured release against its prediction."""
from __future__ import annotations

import math
from pathlib import Path

from analysis import LooShape


def plot_loo(loo: tuple[LooShape, ...], labels: list[str], path: Path, title: str) -> None:
    """Each shape's measured release against its leave-one-out prediction, grams over hours (Fig. 8)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(len(loo), 3)
    nrows = math.ceil(len(loo) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.2 * nrows), dpi=110, squeeze=False,
                             sharey=True)
    for ax, s, label in zip(axes.flat, loo, labels):
        ax.plot(s.t_s / 3600.0, s.measured_g, color="C0", lw=2, label="measured")
        ax.plot(s.t_s / 3600.0, s.predicted_g, "--", color="C3", lw=1.5, label="predicted (left out)")
        ax.set_title(f"{label}\nrel. RMSE {100 * s.rel_rmse:.2f}%", fontsize=8)
        ax.set_xlabel("time (h)")
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("released (g)")
    for ax in list(axes.flat)[len(loo):]:
        ax.axis("off")
    axes[0, 0].legend(loc="lower right", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
