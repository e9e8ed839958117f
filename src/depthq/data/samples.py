"""Which frames of a run are training samples, and their targets (docs/design.md#labels). Pure NumPy.

Frames 0..N-2 have an action, so they are the samples; frame N-1 is where the run ended. The
last `horizon` samples of a run have target 1 (Coll-Q-Net's) if the run's end counts as a
collision: every run's end in the original (its clean-up script marked them all), or only a
bump's (`every_run_end=False`). Depth-Q-Net's target for sample t is the next frame's bins,
d_{t+1} = bins[t + 1], and it drops those same last `horizon` samples.

`action_lag` = 1 pairs frame t with the command computed from frame t−1 (what the original
recorder most likely stored: recorder and controller were separate processes); frame 0 then has
no action and is not a sample.

A Depth-Q-Net that looks `lookahead` = K steps ahead (docs/design.md#lookahead) keeps the one-step
net's samples and extends each target to the frames t+1 … t+K, with the K commands actually sent
(off-policy) as its actions. A step is valid when its frame is one a one-step sample may target:
not past the run's last frame, and not among the frames a collision run's dropped samples would
have targeted. So step 1 is always valid, nothing is dropped, K = 1 is the one-step net, and a
sample near a run's end keeps the steps it has: the rest are masked, not padded, because after a
bump or the time limit there is no frame to learn from, and a made-up one (the last frame held, a
wall at 0 m) would teach depths that were never measured.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from depthq.data.run import RunMeta
from depthq.errors import ConfigError

HORIZON = 5
MIN_FRAMES = 20


@dataclass(frozen=True)
class SampleConfig:
    """Which frames of a dataset's runs are samples, and their targets (`depthq.data.samples`).

    The defaults are the original's: collision targets on the last `horizon` samples of every run
    (`every_run_end`), and the stored command clipped to ±`action_clip` as the action.
    """

    # Coll-Q-Net's collision target: a bump within this many frames (docs/design.md#labels).
    horizon: int = HORIZON
    # Runs shorter than this many frames are not used (docs/design.md#labels).
    min_frames: int = MIN_FRAMES
    # Every run's end counts as a collision, as the original's targets had it; false: only a bump.
    every_run_end: bool = True
    # Recorded commands clipped to ±this (rad/s) before they become actions.
    action_clip: float = 1.0
    # 1: pair frame t with the command of frame t-1 (the original recorder, likely).
    action_lag: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, int) or self.horizon < 1:
            raise ConfigError(f"horizon must be an integer >= 1, got {self.horizon!r}")
        check_min_frames(self.min_frames, self.horizon)
        if not isinstance(self.every_run_end, bool):
            raise ConfigError(f"every_run_end must be true or false, got {self.every_run_end!r}")
        clip = self.action_clip
        if isinstance(clip, bool) or not isinstance(clip, int | float) or not 0 < clip < math.inf:
            raise ConfigError(f"action_clip must be a finite number > 0 rad/s, got {clip!r}")
        if isinstance(self.action_lag, bool) or self.action_lag not in (0, 1):
            raise ConfigError(f"action_lag must be 0 or 1, got {self.action_lag!r}")


def check_min_frames(min_frames: object, horizon: int, what: str = "min_frames") -> None:
    """ConfigError naming `what` and its value unless `min_frames` is an integer >= `horizon` + 2, so
    that every usable run keeps a depth sample."""
    low = horizon + 2
    if isinstance(min_frames, bool) or not isinstance(min_frames, int) or min_frames < low:
        raise ConfigError(f"{what} must be an integer >= {low} (horizon {horizon} + 2: every usable run "
                          f"keeps a depth sample), got {min_frames!r}")


def usable(meta: RunMeta, min_frames: int = MIN_FRAMES) -> bool:
    """Runs shorter than `min_frames` are left out of every subset and view (the paper discards them)."""
    return meta.n_frames >= min_frames


def ends_in_collision(meta: RunMeta, every_run_end: bool) -> bool:
    """Whether the run's last `horizon` samples get collision targets."""
    return every_run_end or meta.collision


def coll_sample_indices(n_frames: int, action_lag: int = 0) -> np.ndarray:
    """Coll-Q-Net's samples: every frame with an action, action_lag..N-2."""
    return np.arange(min(action_lag, n_frames), max(n_frames - 1, 0), dtype=np.int64)


def collision_targets(
    n_frames: int, ended_in_collision: bool, horizon: int = HORIZON, action_lag: int = 0
) -> np.ndarray:
    """y_t for Coll-Q-Net's samples: 1 for the last `horizon` of them if the run ended in a collision."""
    t = coll_sample_indices(n_frames, action_lag)
    if not ended_in_collision:
        return np.zeros(len(t), dtype=np.float32)
    return (t >= n_frames - 1 - horizon).astype(np.float32)


def depth_sample_indices(
    n_frames: int, ended_in_collision: bool, horizon: int = HORIZON, action_lag: int = 0
) -> np.ndarray:
    """Depth-Q-Net's samples t (target bins[t + 1]), without the last `horizon` of a collision run."""
    t = coll_sample_indices(n_frames, action_lag)
    return t[t < n_frames - 1 - horizon] if ended_in_collision else t


def depth_lookahead_frames(
    n_frames: int, ended_in_collision: bool, lookahead: int = 1, horizon: int = HORIZON, action_lag: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth-Q-Net's samples t (S,), the frames of their targets t+1 … t+K (S, K) and which steps
    are valid (S, K). A masked step's frame is clamped to the last valid one (a real frame, never a
    target: the mask says so)."""
    t = depth_sample_indices(n_frames, ended_in_collision, horizon, action_lag)
    last = n_frames - 1 - horizon if ended_in_collision else n_frames - 1
    frames = t[:, None] + np.arange(1, lookahead + 1)
    return t, np.minimum(frames, last), frames <= last


def lookahead_action_indices(
    t: np.ndarray, n_frames: int, lookahead: int = 1, action_lag: int = 0
) -> np.ndarray:
    """(S, K) indices of the stored commands that are the K actions of samples t: step k's is the
    command sent after frame t + k − 1 (t + k − 1 − action_lag). Past the run's last command
    (index N − 2) it is held: only masked steps reach there, and their action still enters the head."""
    return np.minimum(t[:, None] - action_lag + np.arange(lookahead), n_frames - 2)


@dataclass(frozen=True)
class RunSamples:
    """One run's samples for a target: frames t (S,), their targets (S, …), the indices of their
    actions in the run's stored commands ((S,), or (S, K) for K steps), and the valid steps (S, K)
    of a multi-step target (None: every sample's one step is valid)."""

    frames: np.ndarray
    targets: np.ndarray
    commands: np.ndarray
    mask: np.ndarray | None = None


# What a network learns from each run (a network declares its own: `depthq.networks.Network.target`):
# (the run's depth bins (N, bins), whether its end counts as a collision, the sample settings, the
# steps it looks ahead) → its samples (`RunSamples`). `depthq.data.views.view_arrays` takes one.
Target = Callable[[np.ndarray, bool, SampleConfig, int], RunSamples]


def bins_target(bins: np.ndarray, ended: bool, config: SampleConfig, lookahead: int) -> RunSamples:
    """The next frames' depth bins (Depth-Q-Net's): bins[t + 1] … bins[t + K], with the K commands sent;
    a collision run's last `horizon` samples dropped, a masked step's target NaN in every bin."""
    n, horizon, lag = len(bins), config.horizon, config.action_lag
    if lookahead == 1:
        t = depth_sample_indices(n, ended, horizon, lag)
        return RunSamples(t, bins[t + 1], t - lag)
    t, frames, mask = depth_lookahead_frames(n, ended, lookahead, horizon, lag)
    targets = np.where(mask[:, :, None], bins[frames], np.float32(np.nan))
    return RunSamples(t, targets, lookahead_action_indices(t, n, lookahead, lag), mask)


def collision_target(bins: np.ndarray, ended: bool, config: SampleConfig, lookahead: int) -> RunSamples:
    """Whether a collision follows within `horizon` frames (Coll-Q-Net's): every frame with an action.
    It looks ahead through its horizon, so its lookahead must be 1 (else a ConfigError)."""
    if lookahead != 1:
        raise ConfigError(f"a collision target looks ahead through its target (horizon), so its lookahead "
                          f"must be 1, got {lookahead!r}")
    n, lag = len(bins), config.action_lag
    t = coll_sample_indices(n, lag)
    return RunSamples(t, collision_targets(n, ended, config.horizon, lag), t - lag)
