"""A policy from an exported ONNX graph (`depthq export`): onnxruntime and numpy only, as on a robot.

The graph maps uint8 frames and the candidate actions to per-frame, per-action values; the actions
and the selection rule come from the file's metadata, so the file alone defines the policy. A graph
takes a batch of frames (F, H, W, 3), so `act_batch` decides for all of lock-step evaluation's
canyons in one session run; one written before frame batches takes one frame (H, W, 3), run once
per frame. A lookahead
Depth-Q-Net's graph takes candidate sequences (N, K) (docs/design.md#lookahead-selection); its K is
in the metadata (a file without it looks one step ahead).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from depthq.control.action_selection import Selection
from depthq.control.greedy import GreedyPolicy
from depthq.control.policy import Observation
from depthq.errors import ConfigError, DataError


class OnnxPolicy(GreedyPolicy):
    """Greedy policy of an exported Q-net; `last_values` and `selection` as in `QNetPolicy`."""

    def __init__(self, path: Path, threads: int | None = None, selection: Selection | None = None) -> None:
        """`threads`: the session's intra-op threads (None: onnxruntime's default, one per core); an
        evaluation worker runs one, as its torch does."""
        try:
            import onnxruntime as ort  # the optional [deploy] extra: a missing one is a ConfigError
        except ImportError as err:
            raise ConfigError('ONNX policies need onnxruntime: pip install "depthq[deploy]"') from err
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"onnx:{path}: no such file")
        options = ort.SessionOptions()
        # No busy-waiting between runs: a policy decides a few times a second, beside other processes
        # (a robot's ROS nodes, torch in a benchmark), and spinning threads would steal their cores.
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        if threads is not None:
            options.intra_op_num_threads = threads
        try:
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises its own exception types for unreadable models
            raise DataError(f"{path}: not a readable ONNX model ({err})") from err
        meta = self.session.get_modelmeta().custom_metadata_map
        try:
            kind = meta["depthq.kind"]
            actions = np.asarray(json.loads(meta["depthq.actions"]), np.float64)
            self.frame_size = tuple(json.loads(meta["depthq.frame_size"]))
            lookahead = int(meta.get("depthq.lookahead", "1"))
        except (KeyError, ValueError) as err:
            raise DataError(f"{path}: not a depthq policy (metadata {err} missing or invalid)") from err
        self._set_candidates(kind, actions, lookahead, selection)
        self._actions = self.candidates.astype(np.float32)
        frames = self.session.get_inputs()[0]
        self._frames_input, self.frame_batch = frames.name, len(frames.shape) == 4
        self.runtime = f"onnxruntime {ort.__version__}"
        self.path = path
        self.name = f"ONNX:{path.stem}"

    def values(self, image: np.ndarray) -> np.ndarray:
        """Per-candidate predictions for one uint8 frame (H, W, 3): bins (N, n_bins) (a lookahead net's
        (N, K, n_bins)) or probabilities (N,)."""
        return self.batch_values([image])[0]

    def batch_values(self, images: Sequence[np.ndarray]) -> list[np.ndarray]:
        """`values` of each frame: one session run for all of them (a file without frame batches: one
        per frame)."""
        for image in images:
            if image.dtype != np.uint8 or image.shape != (*self.frame_size, 3):
                raise ConfigError(
                    f"{self.path.name}: expected a uint8 frame {(*self.frame_size, 3)}, "
                    f"got {image.dtype} {image.shape}"
                )
        if not self.frame_batch:
            return [self._run(image) for image in images]
        return list(self._run(np.stack(images)))

    def _run(self, frames: np.ndarray) -> np.ndarray:
        return self.session.run(None, {self._frames_input: frames, "actions": self._actions})[0]

    def act_batch(self, observations: Sequence[Observation]) -> list[float]:
        """`act` on each observation (`BatchPolicy`), in one session run; `last_batch_values` holds
        what `last_values` would hold for each."""
        return self.act_on(self.batch_values([obs["image"] for obs in observations]))

    def describe(self) -> dict[str, Any]:
        actions = self.actions.tolist()
        return {"policy": self.name, "kind": self.kind, "onnx": str(self.path), "runtime": self.runtime,
                "frame_batch": self.frame_batch, "actions": actions, **self.selection_record()}
