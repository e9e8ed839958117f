"""What the two learned policies of `depthq.policies` share (a checkpoint's `QNetPolicy`, an exported
graph's `OnnxPolicy`): the candidates a frame's values are predicted for, the rule that picks one of them
(docs/design.md#action-selection, #lookahead-selection), and what Fig. 4 is shown of the values.
A subclass only predicts: `values(image)` for one frame.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from depthq.configio import to_dict
from depthq.control.action_selection import Selection, candidate_sequences
from depthq.control.policy import Observation


class GreedyPolicy:
    """Acts on the candidate its Q-net values best. `last_values` (and `last_batch_values`, one per
    frame of `act_batch`) holds per action its prediction at t+1: (N, n_bins) depth bins (a lookahead
    net's first step of each action held) or (N,) collision probabilities."""

    def _set_candidates(
        self, kind: str, rule: Callable[[np.ndarray, np.ndarray, Selection], float],
        actions: Sequence[float] | np.ndarray, lookahead: int, selection: Selection | None,
    ) -> None:
        """`kind`: the network's name; `rule`: (values, candidates, selection) → the action (its
        network's `choose`)."""
        self.kind = kind
        self._rule = rule
        self.actions = np.asarray(actions, np.float64)
        self.lookahead = lookahead
        self.selection = selection or Selection()
        # The candidates scored per frame: the actions, or a lookahead net's sequences (N, K).
        self.candidates = (self.actions if lookahead == 1
                           else candidate_sequences(self.actions, lookahead, self.selection.switch))
        self.last_values: np.ndarray | None = None
        self.last_batch_values: list[np.ndarray] | None = None

    def values(self, image: np.ndarray) -> np.ndarray:
        """Per-candidate predictions for one uint8 frame (H, W, 3): (N, n_bins), (N, K, n_bins) or (N,)."""
        raise NotImplementedError

    def reset(self, seed: int | None = None) -> None:
        """Stateless between frames."""

    def choose(self, values: np.ndarray) -> float:
        """The action one frame's `values` select (every path that acts calls this)."""
        return self._rule(values, self.candidates, self.selection)

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
        return {"lookahead": self.lookahead, "selection": to_dict(self.selection)}
