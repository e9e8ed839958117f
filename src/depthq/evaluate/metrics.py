"""Table I's per-run and per-policy metrics, as pure functions (docs/design.md#metrics)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

SUCCESS_DISTANCE = 15.0  # metres
COLLISIONS = ("bump", "contact")


def run_success(goal: str, distance: float, end_reason: str) -> bool:
    """A run's success by its canyon family's goal: 'distance' (the paper's: more than 15 m from the
    spawn) or 'end' (the canyon's open end reached, which ends the run before any collision)."""
    return distance > SUCCESS_DISTANCE if goal == "distance" else end_reason == "end"


def distance_to_collision(progress: float, end_reason: str, canyon_length: float) -> float:
    """Progress along the canyon up to the first bump or contact, or up to the time limit; the
    canyon's length only for a run that reached its end. A run that circles or turns back until the
    time limit collides with nothing but gets no further than its progress: crediting it the
    canyon's length (as depthq did before 2026-11-23) ranked a circling policy with the expert."""
    return canyon_length if end_reason == "end" else progress


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
    to_collision = np.array([r["distance_to_collision"] for r in runs])
    closest = np.array([r["closest"] for r in runs])
    return {
        "runs": len(runs),
        "distance_mean": float(dist.mean()),
        "distance_std": float(dist.std()),
        "successes": int(sum(r["success"] for r in runs)),
        "imitation_loss_mean": float(imit.mean()),
        "imitation_loss_std": float(imit.std()),
        "decision_ms_median": float(np.median([r["decision_ms_median"] for r in runs])),
        # metrics that do not saturate when every run succeeds (docs/hard_canyons.md)
        "reached_end": int(sum(r["end_reason"] == "end" for r in runs)),
        "collisions": int(sum(r["end_reason"] in COLLISIONS for r in runs)),
        "progress_mean": float(np.mean([r["progress"] for r in runs])),
        "distance_to_collision_mean": float(to_collision.mean()),
        "distance_to_collision_std": float(to_collision.std()),
        "closest_mean": float(closest.mean()),
        "closest_min": float(closest.min()),
    }
