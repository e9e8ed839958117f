"""Turning Q-net predictions into an action (docs/design.md#action-selection), as pure functions.

The rules by name (`RULES`); which one a network acts by, and its tie tolerance, are the network's
(`depthq.networks`). Farthest nearest bin (Depth-Q-Net's): for each candidate action, the minimum
predicted bin (bins predicted as exactly 0 are ignored: a ReLU output of 0 means "no prediction");
take the action whose closest obstacle is farthest. Lowest collision probability (Coll-Q-Net's): the
action with the lowest. Ties (within the caller's tolerance, `pick_best`) go straight when straight is
among the best, otherwise to the first tied candidate.

A Depth-Q-Net that looks K steps ahead (docs/design.md#lookahead-selection) scores candidate action
sequences (N, K), all in one head pass: each action held for K steps, and with its acting setting
`switch` (`depthq.networks.depth_q_net.Selection`) also each that switches to another action after k
steps. A sequence's score is the nearest bin of each step, combined over the steps by the rule: its
discounted mean (`discounted_nearest_bin`, the default, chosen on val canyons:
docs/design.md#lookahead-selection) or its minimum (`farthest_nearest_bin`); at K = 1 both are the
rule above. The first action of the best sequence is
executed; ties go to the first tied sequence that starts straight, else the first.
"""

from __future__ import annotations

import numpy as np

ACTIONS = (-1.0, 0.0, 1.0)  # the candidate actions a Q-net policy scores per frame
# The rules by name, as a checkpoint records them, and in words, as an exported graph carries them.
RULES = {
    "farthest_nearest_bin": "for each candidate (an action, or a sequence of a lookahead Depth-Q-Net) "
    "the nearest predicted bin (bins of exactly 0 ignored), its minimum over the predicted steps; the "
    "candidate whose nearest bin is farthest, its first action; ties go straight if straight is tied, "
    "else to the first",
    "discounted_nearest_bin": "for each candidate sequence the nearest predicted bin of each step (bins of "
    "exactly 0 ignored), their mean weighted by discount ** (step - 1); the candidate whose mean is "
    "farthest, its first action; ties go straight if straight is tied, else to the first",
    "lowest_collision_probability": "the action with the lowest collision probability; ties go straight "
    "if straight is tied, else to the first",
}
DEPTH_RULES = ("farthest_nearest_bin", "discounted_nearest_bin")


def candidate_sequences(
    actions: tuple[float, ...] | np.ndarray, lookahead: int, switch: bool = False
) -> np.ndarray:
    """(N, K) candidate sequences: each action held for K steps, in `actions`' order; with `switch`
    then, for k = 1 … K−1 and each ordered pair of different actions, a for k steps and b after."""
    actions = np.asarray(actions, np.float64)
    held = np.repeat(actions[:, None], lookahead, axis=1)
    if not switch:
        return held
    switched = [[a] * k + [b] * (lookahead - k)
                for k in range(1, lookahead) for a in actions for b in actions if a != b]
    return np.concatenate([held, np.asarray(switched, np.float64).reshape(-1, lookahead)])


def depth_scores(pred_bins: np.ndarray) -> np.ndarray:
    """(K, n_bins) predicted depths → (K,) nearest predicted obstacle per action (0 if all bins are 0)."""
    pred = np.asarray(pred_bins, dtype=np.float64)
    masked = np.where(pred > 0, pred, np.inf)
    nearest = masked.min(axis=1)
    return np.where(np.isfinite(nearest), nearest, 0.0)


def sequence_scores(pred_bins: np.ndarray, rule: str, discount: float) -> np.ndarray:
    """(N, K, n_bins) predicted depths of N candidate sequences (or (N, n_bins): one step) → (N,)
    scores by `rule`, one of DEPTH_RULES, and its step weight's base `discount`
    (docs/design.md#lookahead-selection); at K = 1 `depth_scores`."""
    pred = np.asarray(pred_bins, dtype=np.float64)
    nearest = depth_scores(pred.reshape(-1, pred.shape[-1])).reshape(pred.shape[0], -1)  # (N, K)
    if rule == "farthest_nearest_bin":
        return nearest.min(axis=1)
    weights = discount ** np.arange(nearest.shape[1])
    return (nearest * weights).sum(axis=1) / weights.sum()


def first_actions(candidates: np.ndarray) -> np.ndarray:
    """The action each candidate executes now: itself, or a sequence's (N, K) first."""
    candidates = np.asarray(candidates, np.float64)
    return candidates[:, 0] if candidates.ndim == 2 else candidates


def pick_best(scores: np.ndarray, actions: np.ndarray, maximise: bool, tol: float) -> float:
    """The best-scoring action; ties (within `tol`: above the last-bit noise a batch's sums add,
    docs/design.md#lockstep) go to 0 if it is tied, else to the first tied."""
    scores = np.asarray(scores, dtype=np.float64)
    best = scores.max() if maximise else scores.min()
    tied = np.flatnonzero(np.abs(scores - best) <= tol)
    straight = [k for k in tied if actions[k] == 0]
    return float(actions[straight[0] if straight else tied[0]])

