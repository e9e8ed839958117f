"""Image trunks by name, and the frame preprocessing every trunk expects.

A trunk maps float images in [0, 1], (B, 3, H, W), to a (B, feature_dim) feature. A frozen trunk
(EfficientNet-Lite0 with ImageNet weights) is a fixed function, so its features can be cached once
per dataset; a trainable one (MobileNet-v1-0.25 from scratch, or EfficientNet-Lite0 fine-tuned) is
trained with the head. A tunable one (the column and grid trunks) can also be split after one of its
MBConv stages (`build_trunk(..., tune_stages=N)`, docs/design.md#tuned-trunk): its early stages stay
frozen, their map cached per frame like a feature (`build_early_trunk`), and its last N stages are
trained with the head from that cache.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from depthq.blocks.efficientnet_lite import FEATURE_DIM as EFFICIENTNET_DIM
from depthq.blocks.efficientnet_lite import (
    LITE0_STAGES,
    EfficientNetLite0,
    efficientnet_lite0,
    fold_batchnorm,
    scale_input,
    stage_blocks,
)
from depthq.blocks.heap import keep_freed_memory
from depthq.blocks.mobilenet_v1 import FEATURE_DIM as MOBILENET_DIM
from depthq.blocks.mobilenet_v1 import MobileNetV1
from depthq.errors import ConfigError

INPUT_SIZE = 128
# Frames per trunk call when frozen: at 128 px, 8–16 frames keep the activations in the 2 MB L2 cache;
# batches of 64 run 2–4× slower per frame on the 2-core reference CPU.
FROZEN_MICRO_BATCH = 16


class Trunk(nn.Module):
    """A named image → feature network.

    A frozen one stays in eval mode, has no trainable parameters, and runs for speed: BatchNorm
    folded (see `fold_batchnorm`), channels-last, in micro-batches of FROZEN_MICRO_BATCH frames.
    """

    def __init__(self, name: str, net: nn.Module, feature_dim: int, frozen: bool) -> None:
        super().__init__()
        self.name = name
        self.net = net
        self.feature_dim = feature_dim
        self.frozen = frozen
        if frozen:
            self.net.requires_grad_(False)
            self.net.to(memory_format=torch.channels_last)
        self.train()

    def train(self, mode: bool = True) -> Trunk:
        """A frozen trunk ignores `train(True)`: its BatchNorm statistics must never move."""
        super().train(mode and not self.frozen)
        return self

    def trained_part(self) -> nn.Module | None:
        """The part of it a checkpoint stores: none of a frozen trunk (rebuilt from the package's
        weights), a tuned one's late stages (its early ones are the package's), else all of it."""
        if self.frozen:
            return None
        return self.net.late if isinstance(self.net, TunedFeatures) else self

    def late_features(self, activations: torch.Tensor) -> torch.Tensor:
        """A tuned trunk's feature from its early stages' map (B, C·S·S), as the activation cache holds it."""
        if not isinstance(self.net, TunedFeatures):
            raise ConfigError(f"trunk {self.name!r} is not tuned from cached activations")
        return self.net.late(activations)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) float in [0, 1] → (B, feature_dim)."""
        if images.ndim != 4 or images.shape[1] != 3:
            raise ConfigError(f"trunk {self.name!r}: expected images (B, 3, H, W), got {tuple(images.shape)}")
        if not self.frozen:
            return self.net.features(images)
        images = images.contiguous(memory_format=torch.channels_last)
        return torch.cat([self.net.features(chunk) for chunk in images.split(FROZEN_MICRO_BATCH)])


@dataclass(frozen=True)
class TrunkSpec:
    """How to build one trunk: `build(pretrained)` returns the network."""

    build: Callable[[bool], nn.Module]
    feature_dim: int
    frozen: bool
    tunable: bool = False  # a `ColumnFeatures` network: its last stages can be tuned (`TunedFeatures`)


def _efficientnet(pretrained: bool) -> nn.Module:
    return fold_batchnorm(efficientnet_lite0(pretrained))


COLUMNS = 4


class ColumnFeatures(nn.Module):
    """EfficientNet-Lite0's last block map, averaged over rows into COLUMNS columns, left to right.

    The global average pool of `features` forgets where in the image an obstacle is, which is what
    a turn changes; the columns keep it at the same size (320 channels × 4 = 1280 = the pooled
    feature's), so the head and its cost stay as they are.
    """

    def __init__(self, net: EfficientNetLite0) -> None:
        super().__init__()
        self.net = net

    def features(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) → (B, 320 · COLUMNS), channel-major: [c0 col0..col3, c1 col0..col3, …]."""
        return self.pool(self.net.block_map(images))

    @staticmethod
    def pool(block_map: torch.Tensor) -> torch.Tensor:
        """The last block map (B, 320, h, w) → the feature."""
        return F.adaptive_avg_pool2d(block_map, (1, COLUMNS)).flatten(1)


def _efficientnet_columns(pretrained: bool) -> nn.Module:
    return ColumnFeatures(_efficientnet(pretrained))


GRID_ROWS = 4  # the last block map's height at 128 px: every cell kept


class GridFeatures(ColumnFeatures):
    """The last block map averaged into GRID_ROWS × COLUMNS cells (at 128 px: the map itself): where an
    obstacle stands in the image, across and up (a near pillar's foot sits low), not only across."""

    @staticmethod
    def pool(block_map: torch.Tensor) -> torch.Tensor:
        """(B, 320, h, w) → (B, 320 · GRID_ROWS · COLUMNS), channel-major, rows top first."""
        return F.adaptive_avg_pool2d(block_map, (GRID_ROWS, COLUMNS)).flatten(1)


def _efficientnet_grid(pretrained: bool) -> nn.Module:
    return GridFeatures(_efficientnet(pretrained))


def _mobilenet(pretrained: bool) -> nn.Module:
    # No MobileNet-v1 weights exist offline: always random init, trained with the head.
    return MobileNetV1()


TRUNKS: dict[str, TrunkSpec] = {
    "efficientnet_lite0": TrunkSpec(_efficientnet, EFFICIENTNET_DIM, frozen=True),  # globally pooled
    "efficientnet_lite0_columns": TrunkSpec(  # the default
        _efficientnet_columns, LITE0_STAGES[-1].out_ch * COLUMNS, frozen=True, tunable=True
    ),
    # The columns' network fine-tuned with the head from its ImageNet weights (the paper's freeze most
    # likely did not take effect, so its trunk was tuned); BatchNorm stays folded, so small batches
    # cannot disturb its statistics. Images every step: a GPU job.
    "efficientnet_lite0_columns_tuned": TrunkSpec(
        _efficientnet_columns, LITE0_STAGES[-1].out_ch * COLUMNS, frozen=False
    ),
    # Rows as well as columns (docs/design.md#trunk): 4× the feature, so pair it with a narrower head.
    "efficientnet_lite0_grid": TrunkSpec(
        _efficientnet_grid, LITE0_STAGES[-1].out_ch * GRID_ROWS * COLUMNS, frozen=True, tunable=True
    ),
    "mobilenet_v1_025": TrunkSpec(_mobilenet, MOBILENET_DIM, frozen=False),  # the paper's, from scratch
}

# Chosen on validation data and `val` canyons (docs/val_choices.md): a Depth-Q-Net on 200 runs passes
# 19/20 val canyons with the columns, 6/20 with the global pool.
DEFAULT_TRUNK = "efficientnet_lite0_columns"


def trunk_spec(name: str) -> TrunkSpec:
    """The spec of the trunk called `name`; an unknown name is a ConfigError listing the valid ones."""
    spec = TRUNKS.get(name)
    if spec is None:
        raise ConfigError(f"unknown trunk {name!r}; valid trunks: {', '.join(sorted(TRUNKS))}")
    return spec


def build_trunk(name: str, pretrained: bool = True, tune_stages: int = 0) -> Trunk:
    """The trunk called `name`; `pretrained=False` skips loading weights (tests, shapes only);
    `tune_stages` N > 0: its last N MBConv stages trained, the others frozen (`TunedFeatures`)."""
    spec = trunk_spec(name)
    check_tune_stages(name, tune_stages)
    keep_freed_memory()  # a trunk allocates tens of MB per call: see depthq.blocks.heap
    if tune_stages:
        split = TunedFeatures(spec.build(pretrained), STAGES - tune_stages)
        return Trunk(name, split, spec.feature_dim, frozen=False)
    return Trunk(name, spec.build(pretrained), spec.feature_dim, spec.frozen)


# --- a trunk tuned from cached activations (docs/design.md#tuned-trunk) ------------------------------

STAGES = len(LITE0_STAGES)  # EfficientNet-Lite0's MBConv stages


def check_tune_stages(trunk: str, tune_stages: object) -> None:
    """`tune_stages`: 0 (the trunk as it is), or 1..STAGES of a tunable trunk (else a ConfigError)."""
    n = tune_stages
    if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= STAGES:
        raise ConfigError(f"train.tune_stages must be an integer in 0..{STAGES} (0: none), got {n!r}")
    if tune_stages and not trunk_spec(trunk).tunable:
        tunable = sorted(name for name, spec in TRUNKS.items() if spec.tunable)
        raise ConfigError(f"train.tune_stages {tune_stages}: trunk {trunk!r} cannot be tuned from cached "
                          f"activations; tunable trunks: {', '.join(tunable)}")


def early_map_shape(frozen_stages: int, size: int) -> tuple[int, int, int]:
    """(channels, side, side) of the map after EfficientNet-Lite0's stem and first `frozen_stages`
    stages, on size × size images: what the activation cache holds per frame."""
    side = size
    for stride in (2, *(s.stride for s in LITE0_STAGES[:frozen_stages])):  # the stem's, then the stages'
        side = -(-side // stride)  # TensorFlow "SAME": ceil(side / stride)
    stem = LITE0_STAGES[0].in_ch
    channels = LITE0_STAGES[frozen_stages - 1].out_ch if frozen_stages else stem
    return channels, side, side


class EarlyStages(nn.Module):
    """EfficientNet-Lite0's stem and first `stages` MBConv stages: the frozen part of a tuned trunk.
    `features` flattens its map (B, C·S·S), as the activation cache stores it per frame."""

    def __init__(self, net: EfficientNetLite0, stages: int) -> None:
        super().__init__()
        self._conv_stem, self._bn0 = net._conv_stem, net._bn0
        self._blocks = nn.ModuleList(net._blocks[: stage_blocks(stages)])

    def features(self, images: torch.Tensor) -> torch.Tensor:
        x = F.relu6(self._bn0(self._conv_stem(scale_input(images))))
        for block in self._blocks:
            x = block(x)
        return x.flatten(1)


class LateStages(nn.Module):
    """The MBConv stages after a tuned trunk's frozen ones, then its pooling: trained with the head."""

    def __init__(
        self, blocks: list[nn.Module], channels: int, pool: Callable[[torch.Tensor], torch.Tensor]
    ) -> None:
        super().__init__()
        self._blocks = nn.ModuleList(blocks)
        self.channels = channels
        self.pool = pool

    def forward(self, activations: torch.Tensor) -> torch.Tensor:
        """The early stages' flattened square map (B, C·S·S) → the feature (B, D)."""
        side = math.isqrt(activations.shape[1] // self.channels)
        if activations.ndim != 2 or self.channels * side * side != activations.shape[1]:
            raise ConfigError(f"tuned trunk: expected activations (B, {self.channels}·S·S), "
                              f"got {tuple(activations.shape)}")
        x = activations.reshape(len(activations), self.channels, side, side)
        for block in self._blocks:
            x = block(x)
        return self.pool(x)


class TunedFeatures(nn.Module):
    """A `ColumnFeatures` network split after MBConv stage `frozen_stages`: `early` frozen (its map
    cached per frame), `late` (the remaining stages and the pooling) trained with the head. The
    same function as the whole network until training moves `late`."""

    def __init__(self, columns: ColumnFeatures, frozen_stages: int) -> None:
        super().__init__()
        net = columns.net
        self.early = EarlyStages(net, frozen_stages).requires_grad_(False)
        channels = early_map_shape(frozen_stages, 1)[0]
        self.late = LateStages(list(net._blocks[stage_blocks(frozen_stages):]), channels, columns.pool)

    def features(self, images: torch.Tensor) -> torch.Tensor:
        return self.late(self.early.features(images))


def early_trunk_name(frozen_stages: int) -> str:
    """The name of EfficientNet-Lite0's first `frozen_stages` stages as a frozen trunk, its activation
    cache's (`depthq.train.features.cache_dir`): one for every tunable trunk (they differ in pooling)."""
    return f"efficientnet_lite0_stage{frozen_stages}"


def build_early_trunk(frozen_stages: int, size: int, pretrained: bool = True) -> Trunk:
    """The frozen early part of a trunk tuned from stage `frozen_stages` + 1, as a frozen trunk whose
    feature is its flattened map on size × size frames (`early_map_shape`)."""
    n = frozen_stages
    if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n < STAGES:
        raise ConfigError(f"early stages must be an integer in 0..{STAGES - 1}, got {n!r}")
    keep_freed_memory()
    channels, side, _ = early_map_shape(frozen_stages, size)
    return Trunk(early_trunk_name(frozen_stages), EarlyStages(_efficientnet(pretrained), frozen_stages),
                 channels * side * side, frozen=True)


def preprocess(images: np.ndarray | torch.Tensor, size: int = INPUT_SIZE) -> torch.Tensor:
    """uint8 frames (B, H, W, 3) or one (H, W, 3) → float (B, 3, size, size) in [0, 1]."""
    return scale_frames(resize_frames(images, size))


def scale_frames(frames: torch.Tensor) -> torch.Tensor:
    """Resized uint8 frames (B, 3, S, S) → float in [0, 1], the trunks' input."""
    return frames.float().div_(255.0)


def resize_frames(images: np.ndarray | torch.Tensor, size: int = INPUT_SIZE) -> torch.Tensor:
    """uint8 frames (B, H, W, 3) or one (H, W, 3) → uint8 (B, 3, size, size), as `preprocess` sees them.

    Bilinear with antialiasing, aspect ratio not kept (as in the paper: 410 × 308 → 128 × 128).
    Resizing runs on uint8 (PyTorch's fast path, ~7× faster than on floats; differs by ≤ 1/255).
    """
    frames = torch.as_tensor(images)
    if frames.ndim == 3:
        frames = frames.unsqueeze(0)
    if frames.dtype != torch.uint8 or frames.ndim != 4 or frames.shape[-1] != 3:
        raise ConfigError(
            f"preprocess: expected uint8 frames (B, H, W, 3), got {frames.dtype} {tuple(frames.shape)}"
        )
    if size < 1:
        raise ConfigError(f"preprocess: size must be ≥ 1, got {size}")
    return F.interpolate(
        frames.permute(0, 3, 1, 2), size=(size, size), mode="bilinear", antialias=True, align_corners=False
    )
