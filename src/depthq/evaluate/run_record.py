"""What an evaluation keeps of one run, decision by decision, and the run's metrics at its end
(docs/design.md#metrics). Driving one canyon at a time (`depthq.evaluate.online.drive`) and
driving several in lock-step (`depthq.evaluate.lockstep`) keep their runs alike through it."""

from __future__ import annotations

from typing import Any

import numpy as np

from depthq.control.policy import Observation
from depthq.evaluate.metrics import distance_from_spawn, distance_to_collision, imitation_loss, run_success
from depthq.evaluate.video import VIDEO_SCALE
from depthq.sim.canyon import FAMILIES
from depthq.sim.env import parse_canyon

FIG4_EVERY, FIG4_FRAMES = 5, 4  # the first canyon keeps every 5th frame; Fig. 4 shows 4, evenly spread


class RunRecord:
    """One run from its reset on: poses, actions, the expert's actions on the same observations and
    decision times. `keep_every` keeps Fig. 4 snapshots; `video` keeps every decision (the camera
    frame at half size) for the MP4."""

    def __init__(self, canyon: str, info: dict[str, Any], keep_every: int = 0, video: bool = False) -> None:
        self.canyon, self.keep_every, self.video = canyon, keep_every, video
        self.poses, self.actions, self.expert_actions = [info["pose"]], [], []
        self.ms, self.snaps, self.frames = [], [], []

    def add(
        self,
        before: Observation,
        expert_action: float,
        action: float,
        ms: float,
        values: np.ndarray | None,
        after: Observation,
        info: dict[str, Any],
    ) -> None:
        """One decision: `action` taken on `before` (the policy's `values`, if it has them), `after`
        and `info` what the env's step returned."""
        step = len(self.actions)
        moment = {"values": values, "true_bins": after["bins"], "pose": self.poses[-1], "action": action}
        if self.keep_every and step % self.keep_every == 0 and values is not None:
            self.snaps.append(_copy({**moment, "step": step, "image": before["image"]}))
        if self.video:
            self.frames.append(_copy({**moment, "image": before["image"][::VIDEO_SCALE, ::VIDEO_SCALE]}))
        self.expert_actions.append(expert_action)
        self.actions.append(action)
        self.ms.append(ms)
        self.poses.append(info["pose"])

    def result(self, info: dict[str, Any]) -> dict[str, Any]:
        """The run's metrics and what its figures need, from the `info` of its last step."""
        poses = np.asarray(self.poses)
        distance = distance_from_spawn(poses)
        snaps = self.snaps
        shown = np.unique(np.linspace(0, len(snaps) - 1, FIG4_FRAMES).round().astype(int)) if snaps else []
        goal, reason = FAMILIES[parse_canyon(self.canyon).family].goal, info["end_reason"]
        return {
            "canyon": self.canyon,
            "distance": distance,
            "path_length": info["path_length"],
            "success": run_success(goal, distance, reason),
            "end_reason": reason,
            "steps": len(self.actions),
            "imitation_loss": imitation_loss(np.array(self.actions), np.array(self.expert_actions)),
            "decision_ms_median": float(np.median(self.ms)),
            "progress": info["progress"],
            "distance_to_collision": distance_to_collision(info["progress"], reason, info["canyon_length"]),
            "closest": info["closest"],
            "canyon_length": info["canyon_length"],
            "poses": poses.astype(np.float32),
            "actions": np.asarray(self.actions, np.float32),
            "snapshots": [snaps[i] for i in shown],
            "video": self.frames,
        }


def _copy(record: dict[str, Any]) -> dict[str, Any]:
    """A moment of a run kept for a figure: arrays copied (the env reuses its buffers)."""
    return {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in record.items()}
