"""Image trunks by name, and the frame preprocessing every trunk expects.

A trunk maps float images in [0, 1], (B, 3, H, W), to a (B, feature_dim) feature. A frozen trunk
(EfficientNet-Lite0 with ImageNet weights) is a fixed function, so its features can be cached once
per dataset; a trainable one (MobileNet-v1-0.25 from scratch, or EfficientNet-Lite0 fine-tuned) is
trained with the head.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from depthq.errors import ConfigError
from depthq.nets.efficientnet_lite import FEATURE_DIM as EFFICIENTNET_DIM
from depthq.nets.efficientnet_lite import LITE0_STAGES, EfficientNetLite0, efficientnet_lite0, fold_batchnorm
from depthq.nets.heap import keep_freed_memory
from depthq.nets.mobilenet_v1 import FEATURE_DIM as MOBILENET_DIM
from depthq.nets.mobilenet_v1 import MobileNetV1

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
        columns = F.adaptive_avg_pool2d(self.net.block_map(images), (1, COLUMNS))
        return columns.flatten(1)


def _efficientnet_columns(pretrained: bool) -> nn.Module:
    return ColumnFeatures(_efficientnet(pretrained))


GRID_ROWS = 4  # the last block map's height at 128 px: every cell kept


class GridFeatures(ColumnFeatures):
    """The last block map averaged into GRID_ROWS × COLUMNS cells (at 128 px: the map itself): where an
    obstacle stands in the image, across and up (a near pillar's foot sits low), not only across."""

    def features(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) → (B, 320 · GRID_ROWS · COLUMNS), channel-major, rows top first."""
        return F.adaptive_avg_pool2d(self.net.block_map(images), (GRID_ROWS, COLUMNS)).flatten(1)


def _efficientnet_grid(pretrained: bool) -> nn.Module:
    return GridFeatures(_efficientnet(pretrained))


def _mobilenet(pretrained: bool) -> nn.Module:
    # No MobileNet-v1 weights exist offline: always random init, trained with the head.
    return MobileNetV1()


TRUNKS: dict[str, TrunkSpec] = {
    "efficientnet_lite0": TrunkSpec(_efficientnet, EFFICIENTNET_DIM, frozen=True),  # globally pooled
    "efficientnet_lite0_columns": TrunkSpec(  # the default
        _efficientnet_columns, LITE0_STAGES[-1].out_ch * COLUMNS, frozen=True
    ),
    # The columns' network fine-tuned with the head from its ImageNet weights (the paper's freeze most
    # likely did not take effect, so its trunk was tuned); BatchNorm stays folded, so small batches
    # cannot disturb its statistics. Images every step: a GPU job.
    "efficientnet_lite0_columns_tuned": TrunkSpec(
        _efficientnet_columns, LITE0_STAGES[-1].out_ch * COLUMNS, frozen=False
    ),
    # Rows as well as columns (docs/design.md#trunk): 4× the feature, so pair it with a narrower head.
    "efficientnet_lite0_grid": TrunkSpec(
        _efficientnet_grid, LITE0_STAGES[-1].out_ch * GRID_ROWS * COLUMNS, frozen=True
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


def build_trunk(name: str, pretrained: bool = True) -> Trunk:
    """The trunk called `name`; `pretrained=False` skips loading weights (tests, shapes only)."""
    spec = trunk_spec(name)
    keep_freed_memory()  # a trunk allocates tens of MB per call: see depthq.nets.heap
    return Trunk(name, spec.build(pretrained), spec.feature_dim, spec.frozen)


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
