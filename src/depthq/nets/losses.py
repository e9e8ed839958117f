"""Training losses of both heads, with per-sample values for the paper's over-fitting signal
(the standard deviation of the per-sample validation loss over a batch, Fig. 5)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from depthq.errors import ConfigError

DEPTH_CLIP = 2.0  # metres; docs/design.md#bins
CLIP_TOLERANCE = 1e-6  # a target within this of the clip counts as "at the clip" (float32 round-off)
DEPTH_LOSSES = ("original", "valid_mean")


def depth_valid_mask(target: torch.Tensor, clip: float = DEPTH_CLIP) -> torch.Tensor:
    """Bins that carry a training signal: target not NaN (no reading) and below the clip (something near)."""
    return torch.isfinite(target) & (target < clip - CLIP_TOLERANCE)


def depth_l1_loss(
    pred: torch.Tensor, target: torch.Tensor, clip: float = DEPTH_CLIP, reduction: str = "original"
) -> tuple[torch.Tensor, torch.Tensor]:
    """L1 over valid bins → (batch loss, per-sample loss (B,)).

    "original" is the authors' loss (docs/design.md#losses): weight 1 where 0.001 < target < clip, then a
    2-wide min-pool of the weights (a bin next to an excluded one on its right is dropped too),
    and the weighted L1 averaged over all bins; the batch loss is the mean of the samples'.

    "valid_mean": the batch loss is the mean absolute error over all valid bins of the batch (sum / count), so
    every valid bin weighs the same whatever sample it is in: a sample with 3 near bins does not
    count as much as one with 26. A sample's own loss is the mean over its valid bins, 0 when it
    has none. A batch with no valid bin gives 0 (with a graph, so `backward` still works).
    """
    if pred.ndim != 2 or pred.shape != target.shape:
        raise ConfigError(
            f"depth_l1_loss: pred {tuple(pred.shape)} and target {tuple(target.shape)} must both be (B, bins)"
        )
    if reduction not in DEPTH_LOSSES:
        raise ConfigError(f"depth loss must be one of {DEPTH_LOSSES}, got {reduction!r}")
    if reduction == "original":
        weight = (depth_valid_mask(target, clip) & (target > 0.001)).to(pred.dtype)
        weight = torch.cat([torch.minimum(weight[:, :-1], weight[:, 1:]), weight[:, -1:]], dim=1)
        per_sample = (weight * (pred - torch.where(weight > 0, target, 0.0)).abs()).mean(dim=1)
        return per_sample.mean(), per_sample
    valid = depth_valid_mask(target, clip)
    # Zero the invalid targets before subtracting: a NaN would poison the gradient even where masked.
    errors = torch.where(valid, (pred - torch.where(valid, target, 0.0)).abs(), 0.0)
    counts = valid.sum(dim=1)
    per_sample = errors.sum(dim=1) / counts.clamp(min=1)
    return errors.sum() / counts.sum().clamp(min=1), per_sample


def coll_bce_loss(logits: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Binary cross-entropy on logits (stable for any logit) → (mean, per-sample (B,))."""
    if logits.ndim != 1 or logits.shape != target.shape:
        raise ConfigError(
            f"coll_bce_loss: logits {tuple(logits.shape)} and target {tuple(target.shape)} must both be (B,)"
        )
    per_sample = F.binary_cross_entropy_with_logits(logits, target.to(logits.dtype), reduction="none")
    return per_sample.mean(), per_sample
