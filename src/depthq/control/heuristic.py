"""The depth heuristic expert: steer towards the sector whose closest obstacle is farthest
(docs/design.md#expert).

Table I's imitation loss compares every policy's actions with this expert's on the same observations.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from depthq.configio import to_dict
from depthq.control.policy import Observation


@dataclass(frozen=True)
class HeuristicConfig:
    """Sectors in degrees (CCW bearings, inclusive); readings are clipped at the LiDAR's range."""

    left: tuple[int, int] = (25, 50)
    centre: tuple[int, int] = (-25, 25)
    right: tuple[int, int] = (-50, -25)
    clip: float = 3.5


def _sector(lo: int, hi: int) -> np.ndarray:
    return np.arange(lo, hi + 1) % 360


class DepthHeuristic:
    """Expert: +1 (left), 0 (straight) or −1 (right) from the LiDAR scan alone."""

    name = "heuristic"

    def __init__(self, config: HeuristicConfig = HeuristicConfig()) -> None:
        self.config = config
        # Centre first, so that ties go straight.
        self._sectors = [_sector(*config.centre), _sector(*config.left), _sector(*config.right)]
        self._actions = np.array([0.0, 1.0, -1.0])

    def reset(self, seed: int | None = None) -> None:
        """Stateless."""

    def act(self, obs: Observation) -> float:
        return heuristic_action(obs["scan"], self._sectors, self._actions, self.config.clip)

    def act_batch(self, observations: Sequence[Observation]) -> list[float]:
        """`act` on each observation (`BatchPolicy`): the rule is a few comparisons per scan."""
        return [self.act(obs) for obs in observations]

    def describe(self) -> dict[str, Any]:
        return {"policy": self.name, "config": to_dict(self.config)}


def heuristic_action(scan: np.ndarray, sectors: list[np.ndarray], actions: np.ndarray, clip: float) -> float:
    """The expert's rule on one scan; invalid readings (0, NaN) are ignored, `inf` counts as `clip`."""
    scan = np.asarray(scan, dtype=np.float64)
    valid = ~(np.isnan(scan) | (scan <= 0))
    clipped = np.where(valid, np.minimum(scan, clip), clip)
    nearest = np.array([clipped[s].min() for s in sectors])
    if np.all(nearest >= clip):
        return 0.0
    return float(actions[int(np.argmax(nearest))])
