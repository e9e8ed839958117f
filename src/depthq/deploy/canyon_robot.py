"""The simulated TurtleBot3 as a robot driven by velocity commands, free of ROS: `depthq ros sim`
(`depthq.deploy.ros_sim`) wraps it in a ROS 1 node, as Gazebo was for the original.

One `tick` is one physics step (`WorldConfig.physics_dt`) at the last command received; it says
which sensors are due (camera at `camera_hz`, LiDAR at 5 Hz, odometry, clock) and whether the
run ended. A run starts at the first command that moves the robot and ends as the evaluation's do
(`depthq.sim.env.CanyonEnv`: a contact, a bump, the canyon's end, the family's time limit), the bump
checked as often as the evaluation checks it (`RobotSimConfig.bump_hz`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from depthq.data.runfile import JPEG_QUALITY, encode_jpeg
from depthq.deploy.robot import STOP, Twist
from depthq.errors import ConfigError
from depthq.sim.canyon import FAMILIES
from depthq.sim.env import SPAWN, CanyonEnv, EnvConfig, end_reason, parse_canyon
from depthq.sim.world import WorldConfig, world_for

LDS01_HZ = 5.0  # the TurtleBot3 LiDAR's scans per second
ODOM_HZ = 30.0  # turtlebot3_core's odometry rate
CLOCK_HZ = 200.0  # /clock messages per simulated second


@dataclass(frozen=True)
class RobotSimConfig:
    """One run of the simulated robot in one canyon."""

    canyon: str = "hard/eval:0"
    camera_hz: float = 30.0  # camera frames per simulated second, as a robot's camera
    time_limit_s: float | None = None  # simulated seconds of driving; none: the family's evaluation limit
    seed: int = 0  # the sensors' noise
    jpeg_quality: int = JPEG_QUALITY  # the compressed frames', as the training data's
    # Simulated seconds of driving after which the camera stops publishing, as a camera driver that
    # dies (what a node's watchdog is for); none: it never stops.
    camera_until_s: float | None = None
    # Bump checks per second of driving, each on a scan of that moment; none: as often as an evaluation
    # checks (`WorldConfig.decision_hz`, 4: once per decision period of the evaluation's robot).
    bump_hz: float | None = None

    def __post_init__(self) -> None:
        parse_canyon(self.canyon)
        if not 0 < self.camera_hz <= 1000:
            raise ConfigError(f"--camera-hz must be in (0, 1000], got {self.camera_hz}")
        if self.time_limit_s is not None and not self.time_limit_s > 0:
            raise ConfigError(f"--time-limit must be > 0 s, got {self.time_limit_s}")
        if self.bump_hz is not None and not 0 < self.bump_hz <= 200:
            raise ConfigError(f"bump_hz must be in (0, 200], got {self.bump_hz}")
        if self.camera_until_s is not None and not self.camera_until_s >= 0:
            raise ConfigError(f"--camera-until must be >= 0 s, got {self.camera_until_s}")
        if not 1 <= self.jpeg_quality <= 95:
            raise ConfigError(f"--jpeg-quality must be in 1..95, got {self.jpeg_quality}")

    @property
    def env(self) -> EnvConfig:
        family = parse_canyon(self.canyon).family
        limit = FAMILIES[family].time_limit_s if self.time_limit_s is None else self.time_limit_s
        return EnvConfig(world=world_for(WorldConfig(), family), time_limit_s=limit)


@dataclass(frozen=True)
class Tick:
    """What one physics step produced: a camera frame (`image`, and as JPEG), a scan (360 readings),
    whether odometry and clock are due, and the run's end reason once it ended."""

    time: float
    jpeg: bytes | None = None
    image: np.ndarray | None = None
    scan: np.ndarray | None = None
    odom: bool = False
    clock: bool = False
    end_reason: str | None = None


class CanyonRobot:
    """The robot in its canyon, moved by the last command (`command`), sensed on schedule (`tick`)."""

    def __init__(self, config: RobotSimConfig) -> None:
        self.config = config
        self.env = CanyonEnv(config.env)
        self.env.reset(seed=config.seed, options={"canyon": parse_canyon(config.canyon)})
        self.world = self.env.world
        self.rng = self.env.np_random
        self.dt = self.world.config.physics_dt
        self.command = STOP
        self.steps = 0  # physics steps since the start (the clock's time: steps × dt)
        self.start: float | None = None  # the clock's time of the first moving command
        self.commands = 0  # commands received since the start
        self.frames = 0
        self.distance = self.path_length = self.progress = 0.0
        self.closest = self.world.config.lidar.range_max + 1.0  # the ray cast's reach, as the env's
        self.end_reason: str | None = None
        self.last_frame: float | None = None  # the driving time of the last frame after the start
        self.stopped: float | None = None  # the driving time of the zero command the robot stands by
        self.trajectory = [self.world.pose]
        self.bump_hz = config.bump_hz or self.world.config.decision_hz

    @property
    def time(self) -> float:
        return self.steps * self.dt

    @property
    def driven(self) -> float:
        """Seconds since the run started (0 before the first moving command)."""
        return 0.0 if self.start is None else self.time - self.start

    def receive(self, twist: Twist) -> None:
        """A command: held until the next, as a TurtleBot3's base holds /cmd_vel (clipped to the
        paper's speed and the world's yaw-rate limit)."""
        world = self.world.config
        speed = float(np.clip(twist.linear_x, -world.speed, world.speed))
        yaw = float(np.clip(twist.angular_z, -world.max_yaw_rate, world.max_yaw_rate))
        if not (math.isfinite(speed) and math.isfinite(yaw)):
            return
        if self.start is None and (speed or yaw):
            self.start = self.time
        if self.start is not None:
            self.commands += 1
            moving = self.command != STOP
            if not (speed or yaw) and moving:
                self.stopped = self.driven
            elif speed or yaw:
                self.stopped = None
        self.command = Twist(speed, yaw)

    def _scan(self) -> np.ndarray:
        scan = self.world.scan(self.rng)
        hits = self.world.last_raycast[self.world.last_raycast >= 0]
        self.closest = min(self.closest, float(hits.min())) if len(hits) else self.closest
        return scan

    def _due_driving(self, hz: float) -> bool:
        """True on the physics step where the driving time passes the next multiple of 1/hz."""
        steps = round(self.driven / self.dt)
        return math.floor(steps * self.dt * hz + 1e-9) > math.floor((steps - 1) * self.dt * hz + 1e-9)

    def _due(self, hz: float) -> bool:
        """True on the physics step where the clock passes the next multiple of 1/hz."""
        now, before = self.steps * self.dt * hz, (self.steps - 1) * self.dt * hz
        return math.floor(now + 1e-9) > math.floor(before + 1e-9)

    def tick(self) -> Tick:
        """One physics step at the held command, then what is due; once the run ended, nothing moves."""
        if self.end_reason is not None:
            return Tick(self.time, end_reason=self.end_reason)
        before = self.world.pose
        contact = self.world.drive(self.command.linear_x, self.command.angular_z)
        self.steps += 1
        pose = self.world.pose
        self.trajectory.append(pose)
        self.path_length += float(np.hypot(*(pose[:2] - before[:2])))
        self.distance = max(self.distance, float(np.hypot(*(pose[:2] - SPAWN[:2]))))
        canyon = self.world.canyon
        self.progress = max(self.progress, canyon.progress(pose[:2]))
        jpeg = scan = image = None
        camera_on = self.start is None or self.config.camera_until_s is None or (
            self.driven < self.config.camera_until_s - 1e-9)
        if camera_on and self._due(self.config.camera_hz):
            image = self.world.image(self.rng)
            jpeg = encode_jpeg(image, self.config.jpeg_quality)
            self.frames += 1
            self.last_frame = self.driven if self.start is not None else None
        if self._due(LDS01_HZ):
            scan = self._scan()
        reading = None  # the scan the bump is checked on, when a check is due
        if self.start is not None and self._due_driving(self.bump_hz):
            reading = scan if scan is not None else self._scan()
        reason = end_reason(self.env.config, self.driven, contact, reading, self.progress, canyon.length)
        self.end_reason = reason
        if reason is not None:
            self.command = STOP
        return Tick(self.time, jpeg, image, scan, self._due(ODOM_HZ), self._due(CLOCK_HZ), reason)

    @property
    def pose(self) -> np.ndarray:
        return self.world.pose

    def summary(self, wall_s: float) -> dict:
        """The run's result, as `depthq drive` prints it, with the commands received and the pace."""
        driven = self.driven
        return {
            "canyon": self.config.canyon,
            "distance": round(self.distance, 3),
            "path_length": round(self.path_length, 3),
            "time": round(driven, 3),
            "end_reason": self.end_reason,
            "progress": round(self.progress, 3),
            "closest": round(self.closest, 3),
            "commands": self.commands,
            "command_hz": round(self.commands / driven, 3) if driven > 0 else 0.0,
            "frames": self.frames,
            "camera_hz": self.config.camera_hz,
            "real_time_factor": round(self.time / wall_s, 3) if wall_s > 0 else None,
            "last_frame": None if self.last_frame is None else round(self.last_frame, 3),
            "stopped": None if self.stopped is None else round(self.stopped, 3),
        }

    def close(self) -> None:
        self.env.close()
