"""Depth bins estimated from the camera: an optional, versioned part of a run file
(docs/formats.md#camera-labels).

A labeller (`depthq label`) estimates, for every stored frame, the 26 depth bins in the LiDAR's
geometry (`depthq.sim.sensors.BinConfig`; the camera's 104° covers the bins' +51°…−52°, so every bin
is estimated), NaN where it has no estimate, as an invalid LiDAR bin. A run file holds them beside the
LiDAR's bins, with the labeller's name and fingerprint, so a training on them says what made its
targets (`TrainConfig.labels`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Which bins become Depth-Q-Net's targets (`TrainConfig.labels`).
LABEL_SOURCES = ("lidar", "camera")
LABELS_VERSION = 1  # of the `camera_bins` dataset in a run file; its own, the run file's stays 1


@dataclass(frozen=True, eq=False)
class CameraLabels:
    """A run's estimated bins (N, n_bins) float32 in metres (NaN = no estimate), and who made them."""

    bins: np.ndarray
    labeller: str  # the labeller's name, e.g. "perception"
    fingerprint: str  # SHA-256 of what fixes its output (`depthq.labellers.labeller`): equal, equal labels

    def __post_init__(self) -> None:
        if not isinstance(self.bins, np.ndarray) or self.bins.dtype != np.float32 or self.bins.ndim != 2:
            got = f"{self.bins.dtype} {self.bins.shape}" if isinstance(self.bins, np.ndarray) else self.bins
            raise ValueError(f"camera labels must be float32 (frames, bins), got {got}")
        if (self.bins < 0).any() or np.isinf(self.bins).any():
            raise ValueError("camera labels must be depths >= 0 m or NaN (no estimate)")
        for name in ("labeller", "fingerprint"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ValueError(f"camera labels need a {name} (a non-empty string)")


def missing_labels_message(root: object, run: str) -> str:
    """What to do when a training asks for camera labels a dataset lacks (its folder, the first run)."""
    return (f"{root} has no camera labels (run {run} holds none): write them first with "
            f"`depthq label {root} --from camera --labeller FOLDER` (a labeller from `depthq labeller`)")
