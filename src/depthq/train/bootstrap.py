"""The bootstrapped Depth-Q-Net target (docs/design.md#bootstrap): the nearest depth along the greedy
policy's future, learnt from the next frame's bins alone (no collision target, no bump).

Per bin, target(s_t, a_t) = (1 − γ)·d_{t+1} + γ·min(d_{t+1}, Q̄(s_{t+1}, a*)), where d_{t+1} is the next
frame's bins (the paper's one-step target), Q̄ the previous epoch's network and a* its greedy action at
s_{t+1} under the policy's own rule (the farthest nearest bin, ties straight). At γ = 0 it is the
one-step target; as γ → 1, the minimum over the whole future the greedy policy would drive. The
mixture is the discounted safety Bellman equation of Fisac et al. (ICRA 2019), which is a contraction
for γ < 1, so fitted iteration converges; per bin, so the head and the selection rule stay as they are.
"""

from __future__ import annotations

import torch

from depthq.blocks.heads import Head
from depthq.control.action_selection import ACTIONS
from depthq.networks import DepthQNet

_STRAIGHT = ACTIONS.index(0.0)


@torch.no_grad()
def greedy_bins(head: Head, features: torch.Tensor) -> torch.Tensor:
    """(B, D) features → (B, bins): the head's bins for the action its policy would pick there."""
    actions = torch.tensor(ACTIONS, dtype=features.dtype, device=features.device)
    n, b = len(ACTIONS), len(features)
    bins = head(features.repeat_interleave(n, dim=0), actions.repeat(b)).reshape(b, n, -1)
    nearest = torch.where(bins > 0, bins, torch.inf).amin(dim=2)
    nearest = torch.where(torch.isfinite(nearest), nearest, 0.0)  # all bins 0: no prediction, score 0
    best = nearest.amax(dim=1, keepdim=True)
    tied = nearest >= best - DepthQNet.tie_tol
    pick = torch.where(tied[:, _STRAIGHT], _STRAIGHT, tied.float().argmax(dim=1))  # first tied otherwise
    return bins[torch.arange(len(features)), pick]


def bootstrapped_targets(
    next_bins: torch.Tensor, head: Head, next_features: torch.Tensor, gamma: float
) -> torch.Tensor:
    """The bootstrapped target of samples whose next frame has bins `next_bins` (B, bins; NaN: no reading,
    kept) and features `next_features` (B, D), with the target network `head` (in eval mode)."""
    future = greedy_bins(head, next_features)
    return (1.0 - gamma) * next_bins + gamma * torch.minimum(next_bins, future)
