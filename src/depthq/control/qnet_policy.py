"""A policy extracted from a trained Depth-Q-Net or Coll-Q-Net: one trunk pass per frame, all
candidate actions through the head in one batch, then the selection rule
(docs/design.md#action-selection)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from depthq.control.action_selection import ACTIONS, select_action
from depthq.control.policy import Observation
from depthq.errors import ConfigError
from depthq.nets.checkpoint import load_qnet, policy_record, selected, weights_stem
from depthq.nets.heads import QNet, probability
from depthq.nets.trunk import preprocess


class QNetPolicy:
    """Greedy policy of a Q-net. `last_values` holds the latest per-action predictions (for Fig. 4):
    (K, n_bins) depth bins for Depth-Q-Net, (K,) collision probabilities for Coll-Q-Net."""

    def __init__(
        self,
        net: QNet,
        kind: str,
        actions: tuple[float, ...] = ACTIONS,
        input_size: int = 128,
        name: str = "qnet",
        source: str | None = None,
        device: torch.device | str = "cpu",
        weights: str | None = None,
    ) -> None:
        if kind not in ("depth", "coll"):
            raise ConfigError(f"unknown Q-net kind {kind!r}; expected 'depth' or 'coll'")
        if not actions or any(not -1 <= a <= 1 for a in actions):
            raise ConfigError(f"candidate actions must be a non-empty list within [-1, 1], got {actions}")
        self.device = torch.device(device)
        self.net = net.to(self.device).eval()
        self.kind = kind
        self.actions = np.asarray(actions, np.float64)
        self._actions_t = torch.tensor(actions, dtype=torch.float32, device=self.device)
        self.input_size = input_size
        self.name = name
        self.source = source
        self.weights = weights
        self.last_values: np.ndarray | None = None

    @classmethod
    def from_checkpoint(
        cls,
        folder: Path,
        which: str | None = None,
        actions: tuple[float, ...] | None = None,
        device: torch.device | str = "cpu",
    ) -> QNetPolicy:
        """The policy of a checkpoint folder: `which` weights (None: the checkpoint's choice) and
        `actions` (None: the checkpoint's) as in `depthq.nets.checkpoint`."""
        net, config = load_qnet(Path(folder), which=which)
        kind = config["train"]["model"]
        return cls(
            net,
            kind,
            policy_record(config).actions if actions is None else actions,
            input_size=int(config["train"]["input_size"]),
            name=f"{'DQN' if kind == 'depth' else 'CQN'}:{Path(folder).name}",
            source=str(folder),
            device=device,
            weights=weights_stem(selected(config, which)),
        )

    def reset(self, seed: int | None = None) -> None:
        """Stateless between frames."""

    @torch.inference_mode()
    def values(self, image: np.ndarray) -> np.ndarray:
        """Per-action predictions for one uint8 frame (H, W, 3)."""
        out = self.net.q_values(preprocess(image, self.input_size).to(self.device), self._actions_t)
        return (probability(out) if self.kind == "coll" else out).cpu().numpy()

    def act(self, obs: Observation) -> float:
        self.last_values = self.values(obs["image"])
        return select_action(self.kind, self.last_values, self.actions)

    def describe(self) -> dict[str, Any]:
        return {
            "policy": self.name,
            "kind": self.kind,
            "checkpoint": self.source,
            "weights": self.weights,
            "actions": self.actions.tolist(),
            "input_size": self.input_size,
        }
