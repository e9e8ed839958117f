"""A policy extracted from a trained Depth-Q-Net or Coll-Q-Net: one trunk pass per frame, all
candidate actions through the head in one batch, then the selection rule
(docs/design.md#action-selection). A lookahead Depth-Q-Net's candidates are action sequences
(docs/design.md#lookahead-selection), scored in the same single head pass."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from depthq.blocks.heads import QNet
from depthq.blocks.trunk import preprocess
from depthq.checkpoint import chosen_weights, load_qnet, policy_record, weights_stem
from depthq.control.action_selection import ACTIONS
from depthq.control.greedy import GreedyPolicy
from depthq.control.policy import Observation
from depthq.errors import ConfigError
from depthq.networks import get_network

# Frames per trunk call in `act_batch` (docs/design.md#lockstep): up to 15 a call, each frame's features
# were those of a one-frame call on both CPUs measured (torch 2.13, one thread), not at 16.
BATCH_FRAMES = 8


class QNetPolicy(GreedyPolicy):
    """Greedy policy of a Q-net of the network `kind` names (`network`). `last_values` holds the latest
    per-action predictions (for Fig. 4): (N, n_bins) depth bins for Depth-Q-Net (a lookahead one's: step
    t+1 of each action held), (N,) collision probabilities for Coll-Q-Net. `acting`: an evaluation's
    acting settings by network name (`EvalConfig.acting`), its network's own used (`Network.Acting`:
    how a Depth-Q-Net makes and scores its candidates)."""

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
        acting: Mapping[str, Any] | None = None,
    ) -> None:
        if not actions or any(not -1 <= a <= 1 for a in actions):
            raise ConfigError(f"candidate actions must be a non-empty list within [-1, 1], got {actions}")
        self.device = torch.device(device)
        self.net = net.to(self.device).eval()
        self._set_candidates(get_network(kind), actions, net.head.config.lookahead, acting)
        self._actions_t = torch.tensor(self.candidates, dtype=torch.float32, device=self.device)
        self.input_size = input_size
        self.name = name
        self.source = source
        self.weights = weights

    @classmethod
    def from_checkpoint(
        cls,
        folder: Path,
        weights: str | None = None,
        actions: tuple[float, ...] | None = None,
        device: torch.device | str = "cpu",
        acting: Mapping[str, Any] | None = None,
    ) -> QNetPolicy:
        """The policy of a checkpoint folder: `weights` (None: the checkpoint's choice) and
        `actions` (None: the checkpoint's) as in `depthq.checkpoint`; `acting` (None: its network's
        defaults) as in `QNetPolicy`."""
        net, config = load_qnet(Path(folder), weights=weights)
        kind = config["train"]["model"]
        return cls(
            net,
            kind,
            policy_record(config).actions if actions is None else actions,
            input_size=int(config["train"]["input_size"]),
            name=f"{get_network(kind).label}:{Path(folder).name}",
            source=str(folder),
            device=device,
            weights=weights_stem(chosen_weights(config, weights, Path(folder))),
            acting=acting,
        )

    @torch.inference_mode()
    def values(self, image: np.ndarray) -> np.ndarray:
        """Per-candidate predictions for one uint8 frame (H, W, 3): (N, n_bins), (N, K, n_bins) or (N,)."""
        return self.candidate_values(self.features([image]))[0]

    @torch.inference_mode()
    def features(self, images: Sequence[np.ndarray]) -> torch.Tensor:
        """The trunk's features (F, D) of F uint8 frames, at most BATCH_FRAMES per trunk call."""
        frames = preprocess(np.stack(images), self.input_size).to(self.device)
        calls = -(-len(images) // BATCH_FRAMES)
        return torch.cat([self.net.trunk(chunk) for chunk in frames.tensor_split(calls)])

    @torch.inference_mode()
    def candidate_values(self, features: torch.Tensor) -> np.ndarray:
        """`values` of F frames' features (F, D), (F, N, …): one head call over all their candidates
        (`QNet.candidate_outputs`)."""
        return self.network.outputs(self.net.candidate_outputs(features, self._actions_t)).cpu().numpy()

    def act_batch(self, observations: Sequence[Observation]) -> list[float]:
        """`act` on each observation (`BatchPolicy`): one trunk pass over all frames, one head pass
        over all their candidates; `last_batch_values` holds what `last_values` would hold for each."""
        return self.act_on(list(self.candidate_values(self.features([obs["image"] for obs in observations]))))

    def describe(self) -> dict[str, Any]:
        return {
            "policy": self.name,
            "kind": self.kind,
            "checkpoint": self.source,
            "weights": self.weights,
            "actions": self.actions.tolist(),
            "input_size": self.input_size,
            **self.selection_record(),
        }
