"""Training losses of both heads, with per-sample values for the paper's over-fitting signal
(the standard deviation of the per-sample validation loss over a batch, Fig. 5)."""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F

from depthq.errors import ConfigError

DEPTH_CLIP = 2.0  # metres; docs/design.md#bins
CLIP_TOLERANCE = 1e-6  # a target within this of the clip counts as "at the clip" (float32 round-off)
DEPTH_LOSSES = ("original", "valid_mean", "relative")
RELATIVE_FLOOR = 0.05  # m: "relative" divides by the target, never by less than this
# A training loss: (outputs, targets) → (batch loss, per-sample loss (B,)); a network's (`depthq.networks`).
LossFn = Callable[[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]


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

    "relative": as "valid_mean", each bin's error divided by its target (at least RELATIVE_FLOOR): an
    error of 10 cm on an obstacle 0.3 m away weighs as much as one of 67 cm at 2 m, as the selection
    rule, which acts on the nearest bin, needs (docs/design.md#losses).
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
    errors = _bin_errors(pred, target, valid, reduction)
    counts = valid.sum(dim=1)
    per_sample = errors.sum(dim=1) / counts.clamp(min=1)
    return errors.sum() / counts.sum().clamp(min=1), per_sample


def lookahead_l1_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    step_weights: torch.Tensor,
    clip: float = DEPTH_CLIP,
    reduction: str = "original",
) -> tuple[torch.Tensor, torch.Tensor]:
    """`depth_l1_loss` over K steps (docs/design.md#lookahead): pred and target (B, K, bins), step k
    weighted by `step_weights[k]` (K,) → (batch loss, per-sample loss (B,)).

    A masked step (past a run's end) has NaN in every target bin, so none of its bins is valid and
    it adds nothing. The weights are normalised over all K steps, not over a sample's valid ones:
    every valid (sample, step) weighs the same wherever it is, as every bin counts in "original"'s
    mean over 26 bins whether valid or not; a sample near a run's end is not worth more per step.

    "original": per sample, the weighted mean over steps of each step's "original" loss; the batch
    loss is the mean of the samples'. "valid_mean": the weighted sum of absolute errors over all
    valid bins of the batch divided by their weighted count (a sample's own: over its valid bins).
    With K = 1 and weight 1 both equal `depth_l1_loss`.
    """
    if pred.ndim != 3 or pred.shape != target.shape:
        raise ConfigError(
            f"lookahead_l1_loss: pred {tuple(pred.shape)} and target {tuple(target.shape)} must both be "
            "(B, steps, bins)"
        )
    if step_weights.shape != pred.shape[1:2]:
        raise ConfigError(f"lookahead_l1_loss: {pred.shape[1]} steps but weights {tuple(step_weights.shape)}")
    if reduction not in DEPTH_LOSSES:
        raise ConfigError(f"depth loss must be one of {DEPTH_LOSSES}, got {reduction!r}")
    weights = step_weights.to(pred)  # its dtype and device
    if reduction == "original":
        _, per_step = depth_l1_loss(pred.flatten(0, 1), target.flatten(0, 1), clip, reduction)
        per_sample = (per_step.view(pred.shape[:2]) * weights).sum(dim=1) / weights.sum()
        return per_sample.mean(), per_sample
    valid = depth_valid_mask(target, clip)
    errors = _bin_errors(pred, target, valid, reduction)
    sums = (errors.sum(dim=2) * weights).sum(dim=1)  # (B,)
    counts = (valid.sum(dim=2).to(pred.dtype) * weights).sum(dim=1)
    tiny = torch.finfo(pred.dtype).tiny  # no valid bin: a sum of 0 over a count of 0 gives 0, with a graph
    return sums.sum() / counts.sum().clamp(min=tiny), sums / counts.clamp(min=tiny)


def _bin_errors(
    pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, reduction: str
) -> torch.Tensor:
    """Each valid bin's absolute error ("relative": over its target), 0 elsewhere. The invalid targets
    are zeroed before subtracting: a NaN would poison the gradient even where masked."""
    clean = torch.where(valid, target, 0.0)
    errors = (pred - clean).abs()
    if reduction == "relative":
        errors = errors / clean.clamp(min=RELATIVE_FLOOR)
    return torch.where(valid, errors, 0.0)


def coll_bce_loss(logits: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Binary cross-entropy on logits (stable for any logit) → (mean, per-sample (B,))."""
    if logits.ndim != 1 or logits.shape != target.shape:
        raise ConfigError(
            f"coll_bce_loss: logits {tuple(logits.shape)} and target {tuple(target.shape)} must both be (B,)"
        )
    per_sample = F.binary_cross_entropy_with_logits(logits, target.to(logits.dtype), reduction="none")
    return per_sample.mean(), per_sample
