"""A policy from an exported ONNX graph (`depthq export`): onnxruntime and numpy only, as on a robot.

The graph maps a uint8 frame and the candidate actions to per-action values; the actions and the
selection rule come from the file's metadata, so the file alone defines the policy. A lookahead
Depth-Q-Net's graph takes candidate sequences (N, K) (docs/design.md#lookahead-selection); its K is
in the metadata (a file without it looks one step ahead).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from depthq.configio import to_dict
from depthq.control.action_selection import Selection, candidate_sequences, select_action
from depthq.control.policy import Observation
from depthq.errors import ConfigError, DataError


class OnnxPolicy:
    """Greedy policy of an exported Q-net; `last_values` and `selection` as in `QNetPolicy`."""

    def __init__(self, path: Path, threads: int | None = None, selection: Selection | None = None) -> None:
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
            self.kind = meta["depthq.kind"]
            self.actions = np.asarray(json.loads(meta["depthq.actions"]), np.float64)
            self.frame_size = tuple(json.loads(meta["depthq.frame_size"]))
            self.lookahead = int(meta.get("depthq.lookahead", "1"))
        except (KeyError, ValueError) as err:
            raise DataError(f"{path}: not a depthq policy (metadata {err} missing or invalid)") from err
        self.selection = selection or Selection()
        self.candidates = (self.actions if self.lookahead == 1
                           else candidate_sequences(self.actions, self.lookahead, self.selection.switch))
        self._actions = self.candidates.astype(np.float32)
        self.path = path
        self.name = f"ONNX:{path.stem}"
        self.last_values: np.ndarray | None = None
        self.last_batch_values: list[np.ndarray] | None = None

    def reset(self, seed: int | None = None) -> None:
        """Stateless between frames."""

    def values(self, image: np.ndarray) -> np.ndarray:
        """Per-candidate predictions for one uint8 frame (H, W, 3): bins (N, n_bins) (a lookahead net's
        (N, K, n_bins)) or probabilities (N,)."""
        if image.dtype != np.uint8 or image.shape != (*self.frame_size, 3):
            raise ConfigError(
                f"{self.path.name}: expected a uint8 frame {(*self.frame_size, 3)}, "
                f"got {image.dtype} {image.shape}"
            )
        return self.session.run(None, {"frame": image, "actions": self._actions})[0]

    def choose(self, values: np.ndarray) -> float:
        """The action one frame's `values` select (every path that acts calls this)."""
        return select_action(self.kind, values, self.candidates, self.selection)

    def shown(self, values: np.ndarray) -> np.ndarray:
        """What `last_values` keeps of one frame's `values`: per action, its prediction at t+1."""
        return values if self.lookahead == 1 else values[: len(self.actions), 0]

    def act(self, obs: Observation) -> float:
        values = self.values(obs["image"])
        self.last_values = self.shown(values)
        return self.choose(values)

    def act_batch(self, observations: Sequence[Observation]) -> list[float]:
        """`act` on each observation (`BatchPolicy`), one graph run per frame: the graph takes one
        frame, as on the robot; `last_batch_values` holds what `last_values` would hold for each."""
        values = [self.values(obs["image"]) for obs in observations]
        self.last_batch_values = [self.shown(v) for v in values]
        return [self.choose(v) for v in values]

    def describe(self) -> dict[str, Any]:
        actions = self.actions.tolist()
        described = {"policy": self.name, "kind": self.kind, "onnx": str(self.path), "actions": actions}
        if self.lookahead > 1:
            described |= {"lookahead": self.lookahead, "selection": to_dict(self.selection)}
        return described
