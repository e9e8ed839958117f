"""MobileNet-v1 at width 0.25, the paper's trunk, up to its last pointwise conv.

No registry package ships its ImageNet weights, so here it starts from random weights and is trained
together with the head (docs/deviations.md#trunk). At 128 px the last map is 4 × 4 × 256; its global
average is the 256-d feature.
"""

from __future__ import annotations

import torch
from torch import nn

WIDTH = 0.25
# (output channels at width 1.0, stride) of the 13 depthwise-separable blocks (Howard et al., 2017).
BLOCKS: tuple[tuple[int, int], ...] = (
    (64, 1),
    (128, 2),
    (128, 1),
    (256, 2),
    (256, 1),
    (512, 2),
    (512, 1),
    (512, 1),
    (512, 1),
    (512, 1),
    (512, 1),
    (1024, 2),
    (1024, 1),
)
STEM_CHANNELS = 32
FEATURE_DIM = int(BLOCKS[-1][0] * WIDTH)  # 256
BN_EPS = 1e-3  # TF-slim's MobileNet value. Momentum stays PyTorch's 0.1: slim's decay 0.9997 suits
# ImageNet-length training, not the few thousand steps this trunk gets.


def _conv_bn_relu6(in_ch: int, out_ch: int, kernel: int, stride: int, groups: int = 1) -> nn.Sequential:
    # Symmetric padding: trained from scratch here, so TF "SAME" alignment buys nothing; the output size
    # (ceil(size / stride)) is the same for the even sizes used.
    return nn.Sequential(
        nn.Conv2d(in_ch, out_ch, kernel, stride, padding=kernel // 2, groups=groups, bias=False),
        nn.BatchNorm2d(out_ch, eps=BN_EPS),
        nn.ReLU6(inplace=True),
    )


class MobileNetV1(nn.Module):
    """MobileNet-v1 trunk on float images in [0, 1], shape (B, 3, H, W); scales inputs to [-1, 1] itself."""

    def __init__(self, width: float = WIDTH) -> None:
        super().__init__()
        channels = int(STEM_CHANNELS * width)
        layers = [_conv_bn_relu6(3, channels, 3, 2)]
        for base, stride in BLOCKS:
            out = int(base * width)
            layers.append(_conv_bn_relu6(channels, channels, 3, stride, groups=channels))  # depthwise
            layers.append(_conv_bn_relu6(channels, out, 1, 1))  # pointwise
            channels = out
        self.layers = nn.Sequential(*layers)
        self.feature_dim = channels

    def feature_map(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 256, H/32, W/32) map of the last pointwise conv (4 × 4 at 128 px)."""
        return self.layers(images * 2.0 - 1.0)  # the Inception/slim input convention

    def features(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 256) globally average-pooled feature."""
        return self.feature_map(images).mean(dim=(2, 3))

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.features(images)
