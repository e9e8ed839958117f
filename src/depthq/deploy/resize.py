"""PyTorch's resize of uint8 frames (Pillow's fixed-point antialiased bilinear algorithm: integer
weights, a horizontal then a vertical pass, each rounded to whole grey levels) in numpy alone: the
ONNX graph's arithmetic (`depthq.deploy.onnx_export.FrameResize`) and a robot's, for a camera frame
of another size than the graph takes (`depthq.deploy.robot.fit`)."""

from __future__ import annotations

import numpy as np


def resize_weights(in_size: int, out_size: int) -> tuple[np.ndarray, int]:
    """Integer weights (out_size, in_size) and their precision in bits of PyTorch's uint8 antialiased
    bilinear resize along one axis (Pillow's algorithm: triangle filter widened by the scale)."""
    scale = in_size / out_size
    support, stretch = (scale, 1.0 / scale) if scale >= 1 else (1.0, 1.0)
    weights = np.zeros((out_size, in_size))
    for i in range(out_size):
        center = scale * (i + 0.5)
        lo, hi = max(int(center - support + 0.5), 0), min(int(center + support + 0.5), in_size)
        w = np.maximum(0.0, 1.0 - np.abs((np.arange(lo, hi) - center + 0.5) * stretch))
        weights[i, lo:hi] = w / w.sum()
    bits = 0
    while bits < 22 and int(0.5 + weights.max() * (1 << (bits + 1))) < (1 << 15):
        bits += 1
    return np.trunc(weights * (1 << bits) + 0.5), bits  # weights ≥ 0: round half up


def rounded(total: np.ndarray, bits: int) -> np.ndarray:
    """A pass's weighted sums back to whole grey levels, as the fixed-point algorithm rounds them."""
    return np.clip(np.floor((total + float(1 << (bits - 1))) * (1.0 / (1 << bits))), 0.0, 255.0)


def resize_frame(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """uint8 (H, W, C) → uint8 (height, width, C), to the bit as torch resizes uint8 frames."""
    rows, row_bits = resize_weights(image.shape[0], size[0])
    cols, col_bits = resize_weights(image.shape[1], size[1])
    planes = image.transpose(2, 0, 1).astype(np.float64)  # (C, H, W)
    planes = rounded(planes @ cols.T, col_bits)  # horizontal pass: (C, H, width)
    planes = rounded(rows @ planes, row_bits)  # vertical pass: (C, height, width)
    return planes.transpose(1, 2, 0).astype(np.uint8)
