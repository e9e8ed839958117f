"""Table I's per-run and per-policy metrics, as pure functions (docs/design.md#metrics)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

SUCCESS_DISTANCE = 15.0  # metres


def distance_from_spawn(poses: np.ndarray) -> float:
    """The largest straight-line distance from the first pose reached during the run."""
    xy = np.asarray(poses, dtype=np.float64)[:, :2]
    return float(np.linalg.norm(xy - xy[0], axis=1).max())


def path_length(poses: np.ndarray) -> float:
    xy = np.asarray(poses, dtype=np.float64)[:, :2]
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())


def imitation_loss(actions: np.ndarray, expert_actions: np.ndarray) -> float:
    """Mean squared difference to the depth heuristic's actions on the same observations."""
    a, e = np.asarray(actions, np.float64), np.asarray(expert_actions, np.float64)
    return float(np.mean((a - e) ** 2)) if len(a) else 0.0


def summarize(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean and std over runs of the online metrics, and the success count."""
    dist = np.array([r["distance"] for r in runs])
    imit = np.array([r["imitation_loss"] for r in runs])
    return {
        "runs": len(runs),
        "distance_mean": float(dist.mean()),
        "distance_std": float(dist.std()),
        "successes": int(sum(r["success"] for r in runs)),
        "imitation_loss_mean": float(imit.mean()),
        "imitation_loss_std": float(imit.std()),
        "decision_ms_median": float(np.median([r["decision_ms_median"] for r in runs])),
    }
