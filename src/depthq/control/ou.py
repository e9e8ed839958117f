"""Ornstein–Uhlenbeck exploration: temporally correlated random yaw rates for data collection
(docs/design.md#exploration)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from depthq.configio import to_dict
from depthq.control.policy import Observation
from depthq.errors import ConfigError


@dataclass(frozen=True)
class OUConfig:
    """x_t = x_{t−1} + theta·(mu − x_{t−1}) + sigma·N(0, 1) from x_0 = 0;  command a_t = scale·x_t.

    As in the original code (docs/design.md#exploration) the command is not clipped (stationary std
    ≈ 0.96 rad/s, up to ≈ 3 rad/s) and the first one is already scale·N(0, 1); the stored command is
    clipped later (`DataConfig.action_clip`), the robot's own limit is `WorldConfig.max_yaw_rate`.
    """

    theta: float = 0.05  # the pull of x back to mu, per step
    mu: float = 0.0  # the mean x is pulled back to
    sigma: float = 1.0  # the noise added to x per step: sigma·N(0, 1)
    scale: float = 0.3  # the command is scale·x, rad/s

    def __post_init__(self) -> None:
        if not 0 <= self.theta <= 1:
            raise ConfigError(f"OU theta must lie in [0, 1], got {self.theta}")
        if not self.sigma >= 0:
            raise ConfigError(f"OU sigma must be >= 0, got {self.sigma}")


class OUPolicy:
    """Ignores the observation; the noise state restarts at 0 with every run (`reset`). Per-run state,
    hence no `act_batch`: lock-step evaluation gives each run an instance of its own."""

    name = "ou"

    def __init__(self, config: OUConfig = OUConfig(), seed: int | None = None) -> None:
        self.config = config
        self.reset(seed)

    def reset(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(seed)
        self._x = 0.0

    def act(self, obs: Observation | None = None) -> float:
        c = self.config
        self._x += c.theta * (c.mu - self._x) + c.sigma * float(self._rng.standard_normal())
        return c.scale * self._x

    def describe(self) -> dict[str, Any]:
        return {"policy": self.name, "config": to_dict(self.config)}
