"""The Depth-Q-Net and Coll-Q-Net heads (docs/design.md#heads), and `QNet`, a trunk plus a head.

Both heads see (feature, action): dropout 0.5 on the feature, the raw action scalar appended, then
FC 4096 + ReLU. Depth-Q-Net ends in FC 26 + ReLU (the depth bins one step later, in metres);
Coll-Q-Net in FC 25 + ReLU → FC 1, returned as a logit so that training can use the numerically
stable BCE-with-logits; `probability` turns logits into P(collision within H).

A Depth-Q-Net head that looks `lookahead` = K steps ahead (docs/design.md#lookahead) appends the K
actions of a sequence and ends in FC K·26: the bins at t+1 … t+K, (B, K, 26). K = 1 is the one-step
head, with the same parameters, initialisation and (B, 26) output.

A Depth-Q-Net head of `form` "per_action" (docs/design.md#heads) separates the scene from the action's
effect: its hidden layer sees the feature alone, and it predicts the bins for each anchor action
(−1, 0, +1) at once; a command between two anchors gets the linear blend of theirs. So one hidden
pass serves every candidate, and what differs between actions is learnt in the output layer alone.

A head with `feature_projection` = P > 0 first maps the D-d trunk feature to P numbers by a fixed
linear map (docs/design.md#heads): the top-P principal directions of the training features
(`pca_projection`), held as buffers, so the optimizer never sees them while checkpoints, policies and
the ONNX graph carry them. P = 0 is the head without it: the same parameters, initialisation, state
dict and outputs.

A Depth-Q-Net head's `bin_gradient` (docs/design.md#dead-outputs) says what its output ReLU passes back:
"relu" its own gradient, none below 0, so a bin whose pre-activation is below 0 for every input is
0 for good (dead: no reading to the policy); "straight_through" the gradient as if the ReLU were not
there, so a bin below 0 where its target is near is pulled up as one above it. The values are the
ReLU's either way, to the bit: the setting changes training only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from depthq.blocks.losses import LossFn
from depthq.blocks.trunk import Trunk
from depthq.errors import ConfigError

# "concat": the action appended to the feature (the paper's); "per_action": bins per anchor action;
# "depth_first": the current bins from the feature, then the next bins from them and the action.
HEAD_FORMS: tuple[str, ...] = ("concat", "per_action", "depth_first")
# What a Depth-Q-Net's output ReLU passes back in training: its own gradient, or the straight-through one.
BIN_GRADIENTS: tuple[str, ...] = ("relu", "straight_through")
ANCHORS = (-1.0, 0.0, 1.0)  # the actions a "per_action" head predicts; a command in between blends two
COLL_HIDDEN = 25
_PCA_CHUNK = 8192  # feature rows per float64 block of the covariance sum: memory stays ≈ 80 MB


def _positive_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


@dataclass(frozen=True)
class HeadConfig:
    """Shape of a head; `feature_dim` must equal the trunk's. Its settings have no defaults here:
    `TrainConfig` declares them (`TrainConfig.head`), a checkpoint's record holds them (#33). Which
    network's head it is (`kind`), and that network's own rules for it, are `depthq.networks`'."""

    kind: str  # the network's name (`depthq.networks.registry`)
    feature_dim: int
    hidden: int
    dropout: float
    action_scale: float  # the action enters the hidden layer as action_scale · a
    lookahead: int  # actions in, steps of outputs (`TrainConfig.lookahead`)
    feature_projection: int  # P > 0: the feature projected to P numbers first; 0: none
    form: str  # one of HEAD_FORMS (`TrainConfig.head_form`)
    output_bias: float  # the initial bias of a layer that outputs depth bins, m (`TrainConfig.output_bias`)
    bin_gradient: str  # one of BIN_GRADIENTS: what the bins' ReLU passes back (`TrainConfig.bin_gradient`)
    n_bins: int = 26  # the depth bins (`depthq.sim.sensors.BinConfig`); not a training setting

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or not self.kind:
            raise ConfigError(f"HeadConfig.kind must be a network's name, got {self.kind!r}")
        for name in ("feature_dim", "hidden", "n_bins", "lookahead"):
            value = getattr(self, name)
            if not _positive_int(value):
                raise ConfigError(f"HeadConfig.{name} must be a positive integer, got {value!r}")
        dropout = self.dropout
        if isinstance(dropout, bool) or not isinstance(dropout, int | float) or not 0 <= dropout < 1:
            raise ConfigError(f"HeadConfig.dropout must be in [0, 1), got {self.dropout!r}")
        if not self.action_scale > 0:
            raise ConfigError(f"HeadConfig.action_scale must be > 0, got {self.action_scale!r}")
        if self.form not in HEAD_FORMS:
            raise ConfigError(f"HeadConfig.form must be one of {HEAD_FORMS}, got {self.form!r}")
        bias = self.output_bias
        if isinstance(bias, bool) or not isinstance(bias, int | float) or not 0 <= bias < math.inf:
            raise ConfigError(f"HeadConfig.output_bias must be a finite number >= 0, got {bias!r}")
        if self.bin_gradient not in BIN_GRADIENTS:
            raise ConfigError(
                f"HeadConfig.bin_gradient must be one of {BIN_GRADIENTS}, got {self.bin_gradient!r}"
            )
        p = self.feature_projection
        if isinstance(p, bool) or not isinstance(p, int) or not 0 <= p <= self.feature_dim:
            raise ConfigError(
                f"HeadConfig.feature_projection must be an integer in 0..{self.feature_dim} "
                f"(0: none), got {p!r}"
            )

    @property
    def input_dim(self) -> int:
        """What the hidden layer takes: the (projected) feature, and the action(s) unless per_action."""
        return (self.feature_projection or self.feature_dim) + (self.form == "concat") * self.lookahead


def pca_projection(features: np.ndarray, size: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The projection onto the top-`size` principal directions of `features` (N, D): weight W
    (size, D) and bias −W·mean (size,), float32, largest variance first.

    Fitted in float64 on the centred features, the covariance summed block by block in a fixed
    order; each direction's sign makes its largest-magnitude component positive, so the same
    features give the same bits (a resumed training's refit equals its stored one).
    """
    n, dim = features.shape
    if not 1 <= size <= dim or n < 2:
        raise ConfigError(f"pca_projection: {size} directions of {n} features of size {dim}")
    blocks = range(0, n, _PCA_CHUNK)
    mean = sum(features[i : i + _PCA_CHUNK].astype(np.float64).sum(axis=0) for i in blocks) / n
    covariance = np.zeros((dim, dim))
    for i in blocks:
        centred = features[i : i + _PCA_CHUNK].astype(np.float64) - mean
        covariance += centred.T @ centred
    _, vectors = np.linalg.eigh(covariance / (n - 1))  # eigenvalues ascending
    top = vectors[:, ::-1][:, :size].T
    top *= np.sign(top[np.arange(size), np.abs(top).argmax(axis=1)])[:, None]
    weight, bias = np.ascontiguousarray(top, dtype=np.float32), (-(top @ mean)).astype(np.float32)
    return torch.from_numpy(weight), torch.from_numpy(bias)


class Projection(nn.Module):
    """feature ↦ W·feature + b, fixed: buffers, not parameters (zero until fitted or loaded)."""

    def __init__(self, feature_dim: int, size: int) -> None:
        super().__init__()
        self.register_buffer("weight", torch.zeros(size, feature_dim))
        self.register_buffer("bias", torch.zeros(size))

    def forward(self, feature: torch.Tensor) -> torch.Tensor:
        return F.linear(feature, self.weight, self.bias)


class Head(nn.Module):
    """The part both heads share: dropout(feature) ⊕ action(s) → FC hidden + ReLU (the feature
    projected first when `feature_projection` > 0)."""

    def __init__(self, config: HeadConfig, output: nn.Module) -> None:
        super().__init__()
        self.config = config
        self.dropout = nn.Dropout(config.dropout)
        self.projection = (Projection(config.feature_dim, config.feature_projection)
                           if config.feature_projection else None)
        self.hidden = nn.Linear(config.input_dim, config.hidden)
        self.output = output
        for module in self.modules():
            if isinstance(module, nn.Linear):  # Glorot init, as in the paper's TensorFlow code
                nn.init.xavier_uniform_(module.weight)
                nn.init.zeros_(module.bias)

    def training_outputs(
        self, feature: torch.Tensor, action: torch.Tensor, current: torch.Tensor | None
    ) -> tuple[torch.Tensor, ...]:
        """What training fits, from features (B, D), actions and the frames' own bins `current`
        (B, n_bins; None unless the data has them): the head's output. Run under the trainer's precision."""
        return (self(feature, action),)

    def training_loss(
        self, outputs: tuple[torch.Tensor, ...], target: torch.Tensor, current: torch.Tensor | None,
        loss_fn: LossFn,
    ) -> torch.Tensor:
        """The training loss of `training_outputs` (float32): the network's `loss_fn` of the output."""
        return loss_fn(outputs[0], target)[0]

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
        if self.projection is not None:
            feature = self.projection(feature)
        if self.config.form != "concat":  # the action enters after the hidden layer
            return F.relu(self.hidden(self.dropout(feature)))
        return F.relu(self.hidden(torch.cat([self.dropout(feature), action], dim=1)))

    @torch.no_grad()
    def fit_projection(self, features: np.ndarray) -> None:
        """Set the projection to `pca_projection` of `features` (N, D): the training split's."""
        if self.projection is None:
            raise ConfigError("fit_projection: this head has no feature projection (feature_projection=0)")
        weight, bias = pca_projection(features, self.config.feature_projection)
        self.projection.weight.copy_(weight)
        self.projection.bias.copy_(bias)


def bins_relu(raw: torch.Tensor, bin_gradient: str) -> torch.Tensor:
    """ReLU of a Depth-Q-Net's raw bin outputs; with `bin_gradient` "straight_through", while a gradient
    is taken, the gradient passes as if there were no ReLU (the values are the ReLU's, bit for bit)."""
    if bin_gradient == "straight_through" and raw.requires_grad:
        return raw + (F.relu(raw) - raw).detach()
    return F.relu(raw)


class DepthHead(Head):
    """Depth-Q-Net head: predicted depth bins at t+1, (B, n_bins), ≥ 0; with lookahead K > 1 at
    t+1 … t+K, (B, K, n_bins). Its output layer's bias starts at `output_bias`."""

    def __init__(self, config: HeadConfig) -> None:
        outputs = len(ANCHORS) if config.form == "per_action" else config.lookahead
        super().__init__(config, nn.Linear(config.hidden, outputs * config.n_bins))
        nn.init.constant_(self.output.bias, config.output_bias)

    def forward(self, feature: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        bins = bins_relu(self.output(self.hidden_features(feature, action)), self.config.bin_gradient)
        if self.config.form == "per_action":
            return torch.einsum("ba,bak->bk", anchor_weights(action.reshape(-1).to(bins.dtype)),
                                bins.reshape(-1, len(ANCHORS), self.config.n_bins))
        k = self.config.lookahead
        return bins if k == 1 else bins.reshape(-1, k, self.config.n_bins)


class DepthFirstHead(Head):
    """Depth-Q-Net head of form "depth_first" (docs/design.md#depth-first): perception, the current
    frame's bins from the feature (hidden layer → FC n_bins), then dynamics, the next frame's bins
    from those and the action (FC hidden + ReLU → FC n_bins + ReLU), as a net given the LiDAR would;
    both bin layers' biases start at `output_bias`.
    Training fits each part to its own LiDAR target (`perceive` to bins[t], `advance` to bins[t+1]
    from the true bins[t]); acting chains them."""

    def __init__(self, config: HeadConfig) -> None:
        n = config.n_bins
        parts = nn.ModuleDict({
            "current": nn.Linear(config.hidden, n),
            "dynamics": nn.Sequential(nn.Linear(n + 1, config.hidden), nn.ReLU(),
                                      nn.Linear(config.hidden, n)),
        })
        super().__init__(config, parts)
        for layer in (parts["current"], parts["dynamics"][-1]):
            nn.init.constant_(layer.bias, config.output_bias)

    def perceive(self, feature: torch.Tensor) -> torch.Tensor:
        """(B, D) → (B, n_bins): the current frame's bins as the feature shows them (unbounded)."""
        return self.output["current"](self.hidden_features(feature, torch.zeros(len(feature))))

    def advance(self, bins: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Current bins (B, n_bins) and actions (B,) → the next frame's bins (B, n_bins), ≥ 0."""
        action = action.reshape(-1, 1).to(bins.dtype) * self.config.action_scale
        return bins_relu(self.output["dynamics"](torch.cat([bins, action], dim=1)), self.config.bin_gradient)

    def forward(self, feature: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.advance(self.perceive(feature).clamp(min=0.0), action)

    def training_outputs(
        self, feature: torch.Tensor, action: torch.Tensor, current: torch.Tensor | None
    ) -> tuple[torch.Tensor, ...]:
        """Each part on its own input (docs/design.md#depth-first): the dynamics' next bins from the true
        current ones, and the perception's current bins."""
        if current is None:
            raise ConfigError("a depth_first head trains on its samples' current bins; the batch has none")
        return self.advance(current, action), self.perceive(feature)

    def training_loss(
        self, outputs: tuple[torch.Tensor, ...], target: torch.Tensor, current: torch.Tensor | None,
        loss_fn: LossFn,
    ) -> torch.Tensor:
        """Each part fitted to its own target: the dynamics by `loss_fn` to the next bins, the
        perception to the current bins (L1 over all of them, invalid as the clip)."""
        advanced, perceived = outputs
        return loss_fn(advanced, target)[0] + (perceived - current).abs().mean()


def anchor_weights(action: torch.Tensor) -> torch.Tensor:
    """(B,) commands → (B, 3) weights of the ANCHORS: linear interpolation, clipped to [−1, 1]."""
    anchors = torch.tensor(ANCHORS, dtype=action.dtype, device=action.device)
    return F.relu(1.0 - (action.clamp(-1.0, 1.0)[:, None] - anchors).abs())


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
    def candidate_outputs(self, features: torch.Tensor, candidates: torch.Tensor) -> torch.Tensor:
        """F frames' features (F, D) and N candidates (N,) or sequences (N, K) → the head on every
        (frame, candidate) row in one call, (F, N, …): depth bins or collision logits. A row's last
        bits may depend on the call's size (docs/design.md#lockstep). Call `.eval()` first."""
        n = len(candidates)
        rows = features.repeat_interleave(n, dim=0)
        actions = candidates.repeat(len(features), *([1] * (candidates.ndim - 1)))
        out = self.head(rows, actions)
        return out.reshape(len(features), n, *out.shape[1:])

    @torch.no_grad()
    def q_values(self, frame: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """One frame, N candidate actions → (N, n_bins) depth bins or (N,) collision logits; with
        lookahead K > 1, N candidate sequences (N, K) → (N, K, n_bins).

        `frame` is an image (1, 3, H, W) in [0, 1] or its feature (1, D) / (D,). The trunk runs once;
        the head runs on all N candidates in one batch (`candidate_outputs`). Call `.eval()` first:
        dropout would make acting random.
        """
        feature = self.trunk(frame) if frame.ndim == 4 else frame.reshape(1, -1)
        if feature.shape[0] != 1:
            raise ConfigError(f"q_values: expected one frame, got a batch of {feature.shape[0]}")
        k = self.head.config.lookahead
        return self.candidate_outputs(feature, actions.reshape(-1) if k == 1 else actions.reshape(-1, k))[0]
