"""The one interface every controller shares: observation in, yaw rate out; and the batch interface
of the policies that decide for several runs in one call (lock-step evaluation)."""

from __future__ import annotations

from collections.abc import Sequence
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


@runtime_checkable
class BatchPolicy(Policy, Protocol):
    """A policy without per-run state that decides for several runs at once (docs/design.md#lockstep).

    `act_batch(observations)[i]` is `act(observations[i])` whatever the other observations: the same
    decision, from values that may differ from one frame's in their last bits (a BLAS kernel may sum a
    batch in another order), so a decision can differ only where two candidates' scores lie within
    that noise of a tie. A policy with per-run state (OU noise) does not offer it; lock-step
    evaluation gives each of its runs an instance of its own.
    """

    def act_batch(self, observations: Sequence[Observation]) -> list[float]: ...
