"""The one interface every controller shares: observation in, yaw rate out."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

Observation = dict[
    str, np.ndarray
]  # {"image": uint8 (H, W, 3), "scan": float32 (360,), "bins": float32 (26,)}


@runtime_checkable
class Policy(Protocol):
    """A controller for one run at a time.

    `reset(seed)` starts a new run (stateful policies such as OU noise restart there);
    `act(obs)` returns the yaw rate in rad/s, in [-1, 1], +left.
    """

    name: str

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, obs: Observation) -> float: ...

    def describe(self) -> dict[str, Any]:
        """JSON-ready description stored with every result the policy produced."""
        ...
