"""MJCF of the world: a fixed number of wall boxes (a canyon is written into them later), the ground,
a sun-like light, and the TurtleBot3 Burger with its camera and LiDAR frame.

The wall count depends only on `CanyonConfig.n_segments` (and the pillars' on `obstacles.count`):
`CanyonWorld.load` moves them in the parsed spec and recompiles (< 1 ms), and one renderer serves
every canyon of a family.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from depthq.errors import ConfigError
from depthq.sim.canyon import CanyonConfig
from depthq.sim.sensors import LidarConfig

WALL_GROUP = 0  # the only geom group the LiDAR sees
ROBOT_GROUP = 1
GROUND_GROUP = 2
WALL_THICKNESS = 0.02
WALL_HEIGHT = 4.0
OBSTACLE_RGBA = "0.45 0.30 0.22 1"


@dataclass(frozen=True)
class CameraConfig:
    """The wide-angle camera: 410 × 308, 104° horizontal FOV, 0.24 m up on the LiDAR's axis."""

    width: int = 410  # frame width, pixels
    height: int = 308  # frame height, pixels
    hfov_deg: float = 104.0  # horizontal field of view, degrees
    mount_height: float = 0.24  # camera height above the floor, m
    noise_std: float = 0.007  # pixel noise's standard deviation, on intensities in [0, 1]

    def __post_init__(self) -> None:
        if (
            not (isinstance(self.width, int) and isinstance(self.height, int))
            or self.width <= 0
            or self.height <= 0
        ):
            raise ConfigError(f"camera resolution must be positive integers, got {self.width}×{self.height}")
        if not 0.0 < self.hfov_deg < 180.0:
            raise ConfigError(f"camera hfov_deg must lie in (0, 180), got {self.hfov_deg}")
        if not self.noise_std >= 0:
            raise ConfigError(f"camera noise_std must be >= 0, got {self.noise_std}")

    @property
    def fovy_deg(self) -> float:
        """MuJoCo's cameras take the vertical field of view."""
        half = math.radians(self.hfov_deg) / 2
        return math.degrees(2 * math.atan(math.tan(half) * self.height / self.width))


@dataclass(frozen=True)
class RobotConfig:
    """TurtleBot3 Burger (the URDF's dimensions). Frame origin: the wheel axle centre."""

    wheel_radius: float = 0.033  # the wheels' radius, m
    wheel_separation: float = 0.160  # between the wheels' centres, m
    length: float = 0.14  # the body's length (its collision box), m
    width: float = 0.18  # the body's width (its collision box), m
    body_height: float = 0.192  # the body's height, m
    sensor_offset_x: float = -0.032  # LiDAR (and camera) sit 3.2 cm behind the axle, as on the robot


def build_mjcf(
    canyon: CanyonConfig, camera: CameraConfig, robot: RobotConfig, lidar: LidarConfig, physics_dt: float
) -> str:
    """The world's MJCF. Walls start parked behind the canyon; `CanyonWorld.load` places them."""
    n_walls = 2 * (canyon.n_segments + 1) + 1
    walls = "\n".join(
        f'    <geom name="wall{i}" type="box" size="0.1 {WALL_THICKNESS / 2} {WALL_HEIGHT / 2}" '
        f'pos="0 {-10 - i} {WALL_HEIGHT / 2}" rgba="0.62 0.62 0.62 1" group="{WALL_GROUP}"/>'
        for i in range(n_walls)
    )
    # Pillars (none in the paper's canyons, whose MJCF stays as it was), parked like the walls.
    ob = canyon.obstacles
    walls += "".join(
        f'\n    <geom name="obstacle{i}" type="cylinder" size="{ob.radius} {ob.height / 2}" '
        f'pos="0 {-10 - n_walls - i} {ob.height / 2}" rgba="{OBSTACLE_RGBA}" group="{WALL_GROUP}"/>'
        for i in range(ob.count)
    )
    hl, hw, h = robot.length / 2, robot.width / 2, robot.body_height
    sx, r = robot.sensor_offset_x, robot.wheel_radius
    return f"""
<mujoco model="depthq_canyon">
  <option timestep="{physics_dt}" gravity="0 0 0" integrator="Euler"/>
  <statistic extent="10" center="0 0 1"/>
  <visual>
    <global offwidth="{max(camera.width, 640)}" offheight="{max(camera.height, 480)}"/>
    <quality shadowsize="0" offsamples="0"/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.25 0.25 0.25" specular="0 0 0"/>
    <map znear="0.002" zfar="5"/>
  </visual>
  <asset>
    <material name="robot" rgba="0.15 0.15 0.15 1"/>
    <texture name="sky" type="skybox" builtin="flat" rgb1="0.78 0.80 0.84" rgb2="0.78 0.80 0.84"
             width="8" height="8"/>
  </asset>
  <worldbody>
    <light name="sun" directional="true" castshadow="false" pos="0 0 10" dir="0.4 0.6 -1"
           diffuse="0.55 0.55 0.55" specular="0 0 0"/>
    <geom name="ground" type="plane" size="200 200 0.1" pos="0 0 0" rgba="0.38 0.38 0.38 1"
          contype="0" conaffinity="0" group="{GROUND_GROUP}"/>
{walls}
    <body name="robot" pos="0 0 0">
      <joint name="x" type="slide" axis="1 0 0" damping="0"/>
      <joint name="y" type="slide" axis="0 1 0" damping="0"/>
      <joint name="yaw" type="hinge" axis="0 0 1" damping="0"/>
      <geom name="chassis" type="box" size="{hl} {hw - 0.015} {h / 2 - 0.005}" pos="{sx} 0 {h / 2 + 0.01}"
            material="robot" group="{ROBOT_GROUP}" mass="1"/>
      <geom name="wheel_left" type="cylinder" size="{r} 0.009" pos="0 {robot.wheel_separation / 2} {r}"
            euler="90 0 0" rgba="0.1 0.1 0.1 1" group="{ROBOT_GROUP}" mass="0.1"/>
      <geom name="wheel_right" type="cylinder" size="{r} 0.009" pos="0 {-robot.wheel_separation / 2} {r}"
            euler="90 0 0" rgba="0.1 0.1 0.1 1" group="{ROBOT_GROUP}" mass="0.1"/>
      <site name="lidar" pos="{sx} 0 {lidar.height}"/>
      <camera name="eye" pos="{sx} 0 {camera.mount_height}" xyaxes="0 -1 0 0 0 1"
              fovy="{camera.fovy_deg:.6f}"/>
    </body>
  </worldbody>
</mujoco>
"""
