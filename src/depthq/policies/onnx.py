"""A policy from an exported ONNX graph (`depthq export`): onnxruntime and numpy only, as on a robot.

The graph maps a uint8 frame and the candidate actions to per-action values; the actions and the
selection rule come from the file's metadata, so the file alone defines the policy. A lookahead
Depth-Q-Net's graph takes candidate sequences (N, K) (docs/design.md#lookahead-selection); its K is
in the metadata (a file without it looks one step ahead).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from depthq.control.greedy import GreedyPolicy
from depthq.errors import ConfigError, DataError
from depthq.networks import get_network


class OnnxPolicy(GreedyPolicy):
    """Greedy policy of an exported Q-net; `last_values` and `acting` as in `QNetPolicy`."""

    def __init__(
        self, path: Path, threads: int | None = None, acting: Mapping[str, Any] | None = None
    ) -> None:
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
            # The rate its training data was collected at (a robot decides at it); None: not recorded.
            record = json.loads(meta.get("depthq.config", "{}"))
            self.decision_hz = float(record["policy"]["decision_hz"]) if "policy" in record else None
            # The canyon family of its training data; None: a robot's recording or an older export.
            self.family = ((record.get("dataset") or {}).get("env") or {}).get("world", {}).get("family")
        except (KeyError, ValueError, TypeError) as err:
            raise DataError(f"{path}: not a depthq policy (metadata {err} missing or invalid)") from err
        self._set_candidates(get_network(kind), actions, lookahead, acting)
        self._actions = self.candidates.astype(np.float32)
        self.runtime = f"onnxruntime {ort.__version__}"
        self.path = path
        self.name = f"ONNX:{path.stem}"

    def values(self, image: np.ndarray) -> np.ndarray:
        """Per-candidate predictions for one uint8 frame (H, W, 3): bins (N, n_bins) (a lookahead net's
        (N, K, n_bins)) or probabilities (N,)."""
        if image.dtype != np.uint8 or image.shape != (*self.frame_size, 3):
            raise ConfigError(
                f"{self.path.name}: expected a uint8 frame {(*self.frame_size, 3)}, "
                f"got {image.dtype} {image.shape}"
            )
        return self.session.run(None, {"frame": image, "actions": self._actions})[0]

    def describe(self) -> dict[str, Any]:
        actions = self.actions.tolist()
        return {"policy": self.name, "kind": self.kind, "onnx": str(self.path), "runtime": self.runtime,
                "actions": actions, **self.selection_record()}
