"""What the two learned policies of `depthq.policies` share (a checkpoint's `QNetPolicy`, an exported
graph's `OnnxPolicy`): the candidates a frame's values are predicted for and the rule that picks one of
them, both its network's, by its acting settings (`Network.Acting`; docs/design.md#action-selection,
#lookahead-selection), and what Fig. 4 is shown of the values.
A subclass only predicts: `values(image)` for one frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from depthq.configio import to_dict
from depthq.control.policy import Observation


class ActingNetwork(Protocol):
    """What a greedy policy asks its network (`depthq.networks.Network`, a layer above this one)."""

    name: str

    def own_acting(self, acting: Mapping[str, Any] | None) -> Any: ...

    def candidates(self, actions: np.ndarray, lookahead: int, acting: Any) -> np.ndarray: ...

    def choose(self, values: np.ndarray, candidates: np.ndarray, acting: Any = None) -> float: ...


class GreedyPolicy:
    """Acts on the candidate its Q-net values best. `last_values` (and `last_batch_values`, one per
    frame of `act_batch`) holds per action its prediction at t+1: (N, n_bins) depth bins (a lookahead
    net's first step of each action held) or (N,) collision probabilities."""

    def _set_candidates(
        self, network: ActingNetwork, actions: Sequence[float] | np.ndarray, lookahead: int,
        acting: Mapping[str, Any] | None,
    ) -> None:
        """`network`: its network, whose `choose` picks the action; `acting`: an evaluation's acting
        settings by network name (`EvalConfig.acting`; None: the defaults), of which `network`'s own
        are used (`self.acting`)."""
        self.network = network
        self.kind = network.name
        self.actions = np.asarray(actions, np.float64)
        self.lookahead = lookahead
        self.acting = network.own_acting(acting)
        # The candidates scored per frame: the actions, or a lookahead net's sequences (N, K).
        self.candidates = network.candidates(self.actions, lookahead, self.acting)
        self.last_values: np.ndarray | None = None
        self.last_batch_values: list[np.ndarray] | None = None

    def values(self, image: np.ndarray) -> np.ndarray:
        """Per-candidate predictions for one uint8 frame (H, W, 3): (N, n_bins), (N, K, n_bins) or (N,)."""
        raise NotImplementedError

    def reset(self, seed: int | None = None) -> None:
        """Stateless between frames."""

    def choose(self, values: np.ndarray) -> float:
        """The action one frame's `values` select (every path that acts calls this)."""
        return self.network.choose(values, self.candidates, self.acting)

    def shown(self, values: np.ndarray) -> np.ndarray:
        """What `last_values` keeps of one frame's `values`: per action, its prediction at t+1."""
        return values if self.lookahead == 1 else values[: len(self.actions), 0]

    def act(self, obs: Observation) -> float:
        values = self.values(obs["image"])
        self.last_values = self.shown(values)
        return self.choose(values)

    def act_batch(self, observations: Sequence[Observation]) -> list[float]:
        """`act` on each observation (`BatchPolicy`), `values` per frame; `last_batch_values` holds
        what `last_values` would hold for each."""
        return self.act_on([self.values(obs["image"]) for obs in observations])

    def act_on(self, values: Sequence[np.ndarray]) -> list[float]:
        """The actions of several frames' `values`, kept in `last_batch_values` as `act` keeps one."""
        self.last_batch_values = [self.shown(v) for v in values]
        return [self.choose(v) for v in values]

    def selection_record(self) -> dict[str, Any]:
        """For `describe`: a one-step net's description stays as it was; a lookahead net's says how it
        selects."""
        if self.lookahead == 1:
            return {}
        return {"lookahead": self.lookahead, "selection": to_dict(self.acting)}
