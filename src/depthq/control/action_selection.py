"""Turning Q-net predictions into an action (docs/design.md#action-selection), as pure functions.

Depth-Q-Net: for each candidate action, the minimum predicted bin (bins predicted as exactly 0 are
ignored: a ReLU output of 0 means "no prediction"); take the action whose closest obstacle is
farthest. Coll-Q-Net: the action with the lowest collision probability. Ties go straight when
straight is among the best, otherwise to the first tied candidate.
"""

from __future__ import annotations

import numpy as np

ACTIONS = (-1.0, 0.0, 1.0)  # the candidate actions a Q-net policy scores per frame
# Each kind's rule by name, as a checkpoint records it, and in words, as an exported graph carries it.
RULE_OF = {"depth": "farthest_nearest_bin", "coll": "lowest_collision_probability"}
RULES = {
    "farthest_nearest_bin": "for each action the nearest predicted bin (bins of exactly 0 ignored); the "
    "action whose nearest bin is farthest; ties go straight if straight is tied, else to the first",
    "lowest_collision_probability": "the action with the lowest collision probability; ties go straight "
    "if straight is tied, else to the first",
}


def depth_scores(pred_bins: np.ndarray) -> np.ndarray:
    """(K, n_bins) predicted depths → (K,) nearest predicted obstacle per action (0 if all bins are 0)."""
    pred = np.asarray(pred_bins, dtype=np.float64)
    masked = np.where(pred > 0, pred, np.inf)
    nearest = masked.min(axis=1)
    return np.where(np.isfinite(nearest), nearest, 0.0)


def pick_best(scores: np.ndarray, actions: np.ndarray, maximise: bool, tol: float = 1e-6) -> float:
    """The best-scoring action; ties (within `tol`) go to 0 if it is tied, else to the first tied."""
    scores = np.asarray(scores, dtype=np.float64)
    best = scores.max() if maximise else scores.min()
    tied = np.flatnonzero(np.abs(scores - best) <= tol)
    straight = [k for k in tied if actions[k] == 0]
    return float(actions[straight[0] if straight else tied[0]])


def select_depth_action(pred_bins: np.ndarray, actions: np.ndarray) -> float:
    return pick_best(depth_scores(pred_bins), np.asarray(actions), maximise=True)


def select_coll_action(collision_prob: np.ndarray, actions: np.ndarray) -> float:
    return pick_best(np.asarray(collision_prob), np.asarray(actions), maximise=False)


def select_action(kind: str, values: np.ndarray, actions: np.ndarray) -> float:
    """The rule of a Q-net of `kind`: 'depth' (predicted bins per action) or 'coll' (probabilities)."""
    if kind == "depth":
        return select_depth_action(values, actions)
    return select_coll_action(values, actions)
