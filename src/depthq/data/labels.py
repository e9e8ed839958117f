"""Which frames of a run are training samples, and their collision labels (SPEC §1.4). Pure NumPy.

Frames 0..N-2 have an action, so they are the samples; frame N-1 is where the run ended. A run
that ended in a collision labels its last `horizon` samples 1 (Coll-Q-Net's target); Depth-Q-Net's
target for sample t is the next frame's bins, d_{t+1} = bins[t + 1], and it drops those same last
`horizon` samples so it never learns from collisions.
"""

from __future__ import annotations

import numpy as np

from depthq.data.run import RunMeta

HORIZON = 5
MIN_FRAMES = 20


def usable(meta: RunMeta, min_frames: int = MIN_FRAMES) -> bool:
    """Runs shorter than `min_frames` are left out of every subset and view (the paper discards them)."""
    return meta.n_frames >= min_frames


def coll_sample_indices(n_frames: int) -> np.ndarray:
    """Coll-Q-Net's samples: every frame with an action, 0..N-2."""
    return np.arange(max(n_frames - 1, 0), dtype=np.int64)


def collision_labels(n_frames: int, ended_in_collision: bool, horizon: int = HORIZON) -> np.ndarray:
    """y_t for t = 0..N-2: 1 for the last `horizon` of them if the run ended in a collision, else 0."""
    labels = np.zeros(max(n_frames - 1, 0), dtype=np.float32)
    if ended_in_collision:
        labels[max(len(labels) - horizon, 0) :] = 1.0
    return labels


def depth_sample_indices(n_frames: int, ended_in_collision: bool, horizon: int = HORIZON) -> np.ndarray:
    """Depth-Q-Net's samples t (target bins[t + 1]): 0..N-2, without the last `horizon` of a collision run."""
    n_samples = max(n_frames - 1, 0)
    if ended_in_collision:
        n_samples = max(n_samples - horizon, 0)
    return np.arange(n_samples, dtype=np.int64)
