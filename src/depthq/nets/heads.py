"""The Depth-Q-Net and Coll-Q-Net heads (docs/design.md#heads), and `QNet`, a trunk plus a head.

Both heads see (feature, action): dropout 0.5 on the feature, the raw action scalar appended, then
FC 4096 + ReLU. Depth-Q-Net ends in FC 26 + ReLU (the depth bins one step later, in metres);
Coll-Q-Net in FC 25 + ReLU → FC 1, returned as a logit so that training can use the numerically
stable BCE-with-logits; `probability` turns logits into P(collision within H).

A Depth-Q-Net head that looks `lookahead` = K steps ahead (docs/design.md#lookahead) appends the K
actions of a sequence and ends in FC K·26: the bins at t+1 … t+K, (B, K, 26). K = 1 is the one-step
head, with the same parameters, initialisation and (B, 26) output.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F
from torch import nn

from depthq.errors import ConfigError
from depthq.nets.trunk import Trunk

HeadKind = Literal["depth", "coll"]
HEAD_KINDS: tuple[str, ...] = ("depth", "coll")
COLL_HIDDEN = 25


def _positive_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


@dataclass(frozen=True)
class HeadConfig:
    """Shape of a head; `feature_dim` must equal the trunk's."""

    kind: HeadKind
    feature_dim: int
    hidden: int = 4096
    n_bins: int = 26
    dropout: float = 0.5
    action_scale: float = 1.0  # the action enters the hidden layer as action_scale · a
    lookahead: int = 1  # actions in, steps of bins out (Depth-Q-Net only; `TrainConfig.lookahead`)

    def __post_init__(self) -> None:
        if self.kind not in HEAD_KINDS:
            raise ConfigError(f"HeadConfig.kind must be one of {HEAD_KINDS}, got {self.kind!r}")
        for name in ("feature_dim", "hidden", "n_bins", "lookahead"):
            value = getattr(self, name)
            if not _positive_int(value):
                raise ConfigError(f"HeadConfig.{name} must be a positive integer, got {value!r}")
        dropout = self.dropout
        if isinstance(dropout, bool) or not isinstance(dropout, int | float) or not 0 <= dropout < 1:
            raise ConfigError(f"HeadConfig.dropout must be in [0, 1), got {self.dropout!r}")
        if not self.action_scale > 0:
            raise ConfigError(f"HeadConfig.action_scale must be > 0, got {self.action_scale!r}")
        if self.kind == "coll" and self.lookahead != 1:
            raise ConfigError(
                f"HeadConfig.lookahead: a Coll-Q-Net head takes one action, got {self.lookahead!r}"
            )


class Head(nn.Module):
    """The part both heads share: dropout(feature) ⊕ action(s) → FC hidden + ReLU."""

    def __init__(self, config: HeadConfig, output: nn.Module) -> None:
        super().__init__()
        self.config = config
        self.dropout = nn.Dropout(config.dropout)
        self.hidden = nn.Linear(config.feature_dim + config.lookahead, config.hidden)
        self.output = output
        for module in self.modules():
            if isinstance(module, nn.Linear):  # Glorot init, as in the paper's TensorFlow code
                nn.init.xavier_uniform_(module.weight)
                nn.init.zeros_(module.bias)

    def hidden_features(self, feature: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(B, D), actions (B,) or (B, 1) (lookahead K > 1: sequences (B, K)) → (B, hidden)."""
        if feature.ndim != 2 or feature.shape[1] != self.config.feature_dim:
            raise ConfigError(
                f"head: expected features (B, {self.config.feature_dim}), got {tuple(feature.shape)}"
            )
        k = self.config.lookahead
        if k > 1 and (action.ndim != 2 or action.shape[1] != k):
            raise ConfigError(f"head: expected action sequences (B, {k}), got {tuple(action.shape)}")
        action = action.reshape(-1, k).to(feature.dtype) * self.config.action_scale
        if action.shape[0] != feature.shape[0]:
            raise ConfigError(f"head: {feature.shape[0]} features but {action.shape[0]} actions")
        return F.relu(self.hidden(torch.cat([self.dropout(feature), action], dim=1)))


class DepthHead(Head):
    """Depth-Q-Net head: predicted depth bins at t+1, (B, n_bins), ≥ 0; with lookahead K > 1 at
    t+1 … t+K, (B, K, n_bins)."""

    def __init__(self, config: HeadConfig) -> None:
        super().__init__(config, nn.Linear(config.hidden, config.lookahead * config.n_bins))

    def forward(self, feature: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        bins = F.relu(self.output(self.hidden_features(feature, action)))
        k = self.config.lookahead
        return bins if k == 1 else bins.reshape(-1, k, self.config.n_bins)


class CollHead(Head):
    """Coll-Q-Net head: collision logit, (B,)."""

    def __init__(self, config: HeadConfig) -> None:
        super().__init__(
            config, nn.Sequential(nn.Linear(config.hidden, COLL_HIDDEN), nn.ReLU(), nn.Linear(COLL_HIDDEN, 1))
        )

    def forward(self, feature: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.output(self.hidden_features(feature, action)).squeeze(1)


def probability(logits: torch.Tensor) -> torch.Tensor:
    """Coll-Q-Net logits → P(collision within H)."""
    return torch.sigmoid(logits)


def build_head(config: HeadConfig) -> Head:
    """The head `config.kind` names."""
    return DepthHead(config) if config.kind == "depth" else CollHead(config)


class QNet(nn.Module):
    """Trunk + head: (images, actions) → depth bins (B, n_bins) or collision logits (B,)."""

    def __init__(self, trunk: Trunk, head: Head) -> None:
        super().__init__()
        if trunk.feature_dim != head.config.feature_dim:
            raise ConfigError(
                f"trunk {trunk.name!r} gives {trunk.feature_dim}-d features, "
                f"head expects feature_dim={head.config.feature_dim}"
            )
        self.trunk = trunk
        self.head = head

    def forward(self, images: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Training on images (trainable trunk); with a frozen trunk, train the head on cached features."""
        return self.head(self.trunk(images), actions)

    @torch.no_grad()
    def q_values(self, frame: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """One frame, N candidate actions → (N, n_bins) depth bins or (N,) collision logits; with
        lookahead K > 1, N candidate sequences (N, K) → (N, K, n_bins).

        `frame` is an image (1, 3, H, W) in [0, 1] or its feature (1, D) / (D,). The trunk runs once;
        the head runs on all N candidates in one batch. Call `.eval()` first: dropout would make
        acting random.
        """
        feature = self.trunk(frame) if frame.ndim == 4 else frame.reshape(1, -1)
        if feature.shape[0] != 1:
            raise ConfigError(f"q_values: expected one frame, got a batch of {feature.shape[0]}")
        k = self.head.config.lookahead
        actions = actions.reshape(-1) if k == 1 else actions.reshape(-1, k)
        return self.head(feature.expand(actions.shape[0], -1), actions)
