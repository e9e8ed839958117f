"""Top-down maps: canyon walls (and pillars) and driven trajectories, the way Fig. 3 (right) shows a run."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.sim.canyon import Canyon


def draw_run(
    ax, canyon: Canyon, poses: np.ndarray | None, title: str | None = None, span: float | None = None
):
    """Walls in grey, the path in colour from the spawn (circle) to the end (cross)."""
    for wall in (canyon.left, canyon.right, canyon.back):
        ax.plot(wall[:, 0], wall[:, 1], color="0.35", lw=1.0)
    for x, y, r in canyon.obstacles:
        ax.add_patch(plt.Circle((x, y), r, color="0.35"))
    ymax = 8.0
    if poses is not None and len(poses):
        ax.plot(poses[:, 0], poses[:, 1], color="tab:red", lw=1.2)
        ax.plot(*poses[0, :2], "o", color="tab:green", ms=4)
        ax.plot(*poses[-1, :2], "x", color="tab:red", ms=6)
        ymax = max(ymax, float(poses[:, 1].max()) + 3)
    if span is not None:
        ymax = span
    ax.set_ylim(-2.5, ymax)
    keep = canyon.left[:, 1] <= ymax
    xs = np.concatenate([canyon.left[keep, 0], canyon.right[keep, 0]])
    ax.set_xlim(xs.min() - 1, xs.max() + 1)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6)
    if title:
        ax.set_title(title, fontsize=7)


def plot_runs(
    runs: Sequence[tuple[Canyon, np.ndarray | None]],
    titles: Sequence[str] | None = None,
    path: str | Path | None = None,
    cols: int = 10,
):
    """One panel per run; saved as PNG when `path` is given. Returns the figure."""
    n = len(runs)
    cols = min(cols, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(1.6 * cols + 0.5, 5.0 * rows), squeeze=False)
    for k, ax in enumerate(axes.flat):
        if k >= n:
            ax.axis("off")
            continue
        canyon, poses = runs[k]
        draw_run(ax, canyon, poses, titles[k] if titles else str(canyon.id))
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig
