"""The task (dm_control's "task"): drive at constant speed through a canyon until a bump, a
contact with a wall, the canyon's open end or the time limit. Gymnasium env `depthq/Canyon-v0`.

Observation: {"image": uint8 (308, 410, 3) camera frame with pixel noise,
              "scan": float32 (360,) LiDAR (index = bearing in degrees, CCW; inf = nothing in range,
                      0 = invalid), "bins": float32 (26,) depth bins left→right (an invalid reading
                      counts as far, as in the original: `BinConfig.invalid_as_far`)}.
Action: yaw rate in rad/s, shape (1,), clipped to ±`world.max_yaw_rate` (1 by default); +a turns left.
One step is one camera frame: `world.decision_hz` decisions per second.
Reward: metres gained on the furthest straight-line distance from the spawn point (what Table I measures).
The world is built for the family of the canyon a reset loads (`depthq.sim.world.world_for`).
Info also tracks `progress` (furthest point reached along the canyon's centre line, m) and `closest`
(the smallest noise-free ray-cast distance from the LiDAR to a wall or pillar so far, m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from depthq.errors import ConfigError
from depthq.sim.canyon import CanyonId, generate_canyon
from depthq.sim.sensors import BinConfig, BumpConfig, bump, depth_bins
from depthq.sim.world import CanyonWorld, WorldConfig, world_for

SPAWN = (0.0, 0.0, math.pi / 2)  # (x, y, yaw): at the origin, facing +y
COLLISIONS = ("bump", "contact")
END_REASONS = (*COLLISIONS, "end", "time_limit")  # "end": the canyon's open end reached


@dataclass(frozen=True)
class EnvConfig:
    """Everything that defines an episode: the world, the sensors' post-processing, the limits."""

    world: WorldConfig = field(default_factory=WorldConfig)
    bins: BinConfig = field(default_factory=BinConfig)  # the LiDAR's depth bins
    bump: BumpConfig = field(default_factory=BumpConfig)  # the bump that ends a run
    time_limit_s: float = 45.0  # seconds before a run is cut

    def __post_init__(self) -> None:
        if not self.time_limit_s > 0:
            raise ConfigError(f"time_limit_s must be > 0, got {self.time_limit_s}")


def parse_canyon(value: Any) -> CanyonId:
    """Accept CanyonId, 'eval:3' or ('eval', 3)."""
    if isinstance(value, CanyonId):
        return value
    if isinstance(value, str):
        return CanyonId.parse(value)
    if isinstance(value, tuple | list) and len(value) == 2:
        return CanyonId(str(value[0]), int(value[1]))
    raise ConfigError(f"canyon must be 'stream:index' or (stream, index), got {value!r}")


def end_reason(
    config: EnvConfig, time: float, contact: bool, scan: np.ndarray | None, progress: float, length: float
) -> str | None:
    """Why a run ends after a step at `time` s of driving, the first that holds of: a contact, a bump
    (on `scan`, after the grace; None: no scan checked this step), the canyon's end reached (`progress`
    along its `length`), the time limit; None: the run goes on. `depthq ros sim`'s robot ends by it too."""
    if contact:
        return "contact"
    if scan is not None and time >= config.bump.grace_s - 1e-9 and bump(scan, config.bump):
        return "bump"
    if progress >= length:
        return "end"
    if time >= config.time_limit_s - 1e-9:
        return "time_limit"
    return None


class CanyonEnv(gym.Env):
    """A TurtleBot3 Burger in a random canyon, seen through its camera and LiDAR."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self, config: EnvConfig | None = None, render_mode: str | None = None, camera: bool = True
    ) -> None:
        """`camera=False` skips rendering (the image stays black), for what needs no pixels: run
        statistics and the LiDAR oracle (`depthq.evaluate.probe`)."""
        self.config = config or EnvConfig()
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"unknown render_mode {render_mode!r}; expected None or 'rgb_array'")
        self.render_mode = render_mode
        cam = self.config.world.camera
        self.observation_space = spaces.Dict(
            {
                "image": spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8),
                "scan": spaces.Box(0.0, np.inf, (self.config.world.lidar.n_rays,), np.float32),
                "bins": spaces.Box(0.0, self.config.bins.clip, (self.config.bins.n_bins,), np.float32),
            }
        )
        limit = self.config.world.max_yaw_rate
        self.action_space = spaces.Box(-limit, limit, (1,), np.float32)
        self._camera = camera
        self.world = CanyonWorld(self.config.world, render=camera)
        self._black = None if camera else np.zeros(self.observation_space["image"].shape, np.uint8)
        self.dt = self.config.world.period
        self.metadata = {**self.metadata, "render_fps": self.config.world.decision_hz}
        self.canyon_id: CanyonId | None = None
        self.trajectory: list[np.ndarray] = []
        self._obs: dict[str, np.ndarray] | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        if "canyon" in options:
            canyon_id = parse_canyon(options["canyon"])
        else:
            index = int(self.np_random.integers(0, 2**31 - 1))
            canyon_id = CanyonId("train", index, self.config.world.family)
        if canyon_id != self.canyon_id:
            world = world_for(self.config.world, canyon_id.family)
            if world != self.world.config:  # another family: its own walls, pillars and look
                self.world.close()
                self.world = CanyonWorld(world, render=self._camera)
            appearance = np.random.default_rng(canyon_id.appearance_seed)
            self.world.load(generate_canyon(canyon_id, world.canyon), appearance)
            self.canyon_id = canyon_id
        self.world.place(*SPAWN)
        self.world.start_run(self.np_random)  # a textured look's camera, drawn per run (none otherwise)
        self.time = 0.0
        self.path_length = 0.0
        self.distance = 0.0
        self.progress = 0.0
        self.closest = self.config.world.lidar.range_max + 1.0  # the ray cast's reach
        self.trajectory = [self.world.pose]
        self._obs = self._observe()
        return self._obs, self._info(None)

    def step(self, action):
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.size != 1 or not np.isfinite(a[0]):
            raise ConfigError(f"action must be one finite yaw rate, got {action!r}")
        limit = self.config.world.max_yaw_rate
        yaw_rate = float(np.clip(a[0], -limit, limit))
        before = self.world.pose
        contact = self.world.advance(yaw_rate)
        self.time = round(self.time + self.dt, 9)
        pose = self.world.pose
        self.trajectory.append(pose)
        self.path_length += float(np.hypot(*(pose[:2] - before[:2])))
        gained = max(0.0, float(np.hypot(*(pose[:2] - SPAWN[:2]))) - self.distance)
        self.distance += gained
        canyon = self.world.canyon
        progress = canyon.progress(pose[:2])
        self.progress = max(self.progress, progress)
        self._obs = self._observe()
        reason = end_reason(self.config, self.time, contact, self._obs["scan"], progress, canyon.length)
        terminated = reason in (*COLLISIONS, "end")
        return self._obs, gained, terminated, reason == "time_limit", self._info(reason)

    def _observe(self) -> dict[str, np.ndarray]:
        scan = self.world.scan(self.np_random)
        hits = self.world.last_raycast[self.world.last_raycast >= 0]
        if len(hits):
            self.closest = min(self.closest, float(hits.min()))
        return {
            "image": self.world.image(self.np_random) if self._black is None else self._black,
            "scan": scan,
            "bins": depth_bins(scan, self.config.bins),
        }

    def _info(self, end_reason: str | None) -> dict[str, Any]:
        return {
            "pose": self.trajectory[-1].copy(),
            "time": self.time,
            "path_length": self.path_length,
            "distance": self.distance,
            "progress": self.progress,
            "closest": self.closest,
            "canyon_length": self.world.canyon.length,
            "canyon": str(self.canyon_id),
            "end_reason": end_reason,
        }

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array" and self._obs is not None:
            return self._obs["image"]
        return None

    def top_down(self, path: str | None = None):
        """A top-down map of the canyon with the trajectory so far (matplotlib figure, saved if `path`)."""
        from depthq.sim.topdown import plot_runs  # matplotlib: envs that never draw a map skip it

        return plot_runs([(self.world.canyon, np.array(self.trajectory))], path=path)

    def close(self) -> None:
        self.world.close()
