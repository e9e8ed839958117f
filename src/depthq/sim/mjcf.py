"""MJCF of the world: a fixed number of wall boxes (a canyon is written into them later), the ground,
a sun-like light, and the TurtleBot3 Burger with its camera and LiDAR frame.

The wall count depends only on `CanyonConfig.n_segments` (and the pillars' on `obstacles.count`):
`CanyonWorld.load` moves them in the parsed spec and recompiles (< 1 ms), and one renderer serves
every canyon of a family.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from depthq.errors import ConfigError
from depthq.sim.canyon import CanyonConfig
from depthq.sim.look import SURFACES
from depthq.sim.sensors import LidarConfig
from depthq.sim.textures import TEXTURE_METRES, TEXTURE_SIZE

WALL_GROUP = 0  # the only geom group the LiDAR sees
ROBOT_GROUP = 1
GROUND_GROUP = 2
# The textured looks' visual copies of the walls and pillars: the camera sees them instead of the
# collision geoms (hidden from it), the LiDAR and the physics never see them.
VISUAL_GROUP = 3
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
    canyon: CanyonConfig,
    camera: CameraConfig,
    robot: RobotConfig,
    lidar: LidarConfig,
    physics_dt: float,
    textured: bool = False,
    shadows: bool = False,
) -> str:
    """The world's MJCF. Walls start parked behind the canyon; `CanyonWorld.load` places them.
    `textured`: visual copies of walls and pillars that carry textures (`textured_assets`)."""
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
    assets, ground = "", 'rgba="0.38 0.38 0.38 1"'
    sky = """<texture name="sky" type="skybox" builtin="flat" rgb1="0.78 0.80 0.84" rgb2="0.78 0.80 0.84"
             width="8" height="8"/>"""
    if textured:
        assets, sky, ground = textured_assets(canyon.obstacles.radius, canyon.obstacles.height)
        walls += textured_geoms(canyon.obstacles.count)
    hl, hw, h = robot.length / 2, robot.width / 2, robot.body_height
    sx, r = robot.sensor_offset_x, robot.wheel_radius
    return f"""
<mujoco model="depthq_canyon">
  <option timestep="{physics_dt}" gravity="0 0 0" integrator="Euler"/>
  <statistic extent="10" center="0 0 1"/>
  <visual>
    <global offwidth="{max(camera.width, 640)}" offheight="{max(camera.height, 480)}"/>
    <quality shadowsize="{2048 if shadows else 0}" offsamples="0"/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.25 0.25 0.25" specular="0 0 0"/>
    <map znear="0.002" zfar="5"/>
  </visual>
  <asset>
    <material name="robot" rgba="0.15 0.15 0.15 1"/>
    {sky}{assets}
  </asset>
  <worldbody>
    <light name="sun" directional="true" castshadow="{str(shadows).lower()}" pos="0 0 10" dir="0.4 0.6 -1"
           diffuse="0.55 0.55 0.55" specular="0 0 0"/>
    <geom name="ground" type="plane" size="200 200 0.1" pos="0 0 0" {ground}
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


def textured_assets(radius: float, height: float) -> tuple[str, str, str]:
    """A texture and material per surface (world-scaled: one repeat per `TEXTURE_METRES` m), a gradient
    sky, the pillars' mesh; and the ground's material attribute. `CanyonWorld.load` writes the
    textures' pixels and the sky's colours per canyon."""
    per_metre = 1 / TEXTURE_METRES
    assets = "".join(
        f'\n    <texture name="tex_{s}" type="2d" builtin="flat" rgb1="0.5 0.5 0.5" width="{TEXTURE_SIZE}" '
        f'height="{TEXTURE_SIZE}"/>\n    <material name="mat_{s}" texture="tex_{s}" texuniform="true" '
        f'texrepeat="{per_metre} {per_metre}" specular="0.1" shininess="0.2"/>'
        for s in SURFACES
    )
    sky = """<texture name="sky" type="skybox" builtin="gradient" rgb1="0.5 0.6 0.8" rgb2="0.8 0.8 0.8"
             width="64" height="64"/>"""
    # Placeholders (a tetrahedron, so that the model compiles) until `CanyonWorld.load` writes a canyon.
    walls = "".join(f'\n    <mesh name="wall_{s}" vertex="0 0 0 1 0 0 0 1 0 0 0 1" inertia="shell"/>'
                    for s in WALL_SIDES)
    return assets + "\n    " + pillar_mesh(radius, height) + walls, sky, 'material="mat_floor"'


def pillar_mesh(radius: float, height: float, sides: int = 32) -> str:
    """A cylinder whose side is unrolled into texture coordinates in metres (around, up): undistorted
    texture, which MuJoCo's 2D mapping of a cylinder geom is not (it streaks)."""
    angles = np.linspace(0, 2 * math.pi, sides + 1)
    vertices, uv = [], []
    for z in (-height / 2, height / 2):
        for a in angles:
            vertices.append((radius * math.cos(a), radius * math.sin(a), z))
            uv.append((a * radius, z + height / 2))
    faces = []
    for k in range(sides):
        low, high = k, sides + 1 + k
        faces += [(low, low + 1, high + 1), (low, high + 1, high)]
    for z, order in ((-height / 2, -1), (height / 2, 1)):  # caps: fans around their centres
        vertices.append((0.0, 0.0, z))
        uv.append((0.0, 0.0))
        centre, ring = len(vertices) - 1, 0 if z < 0 else sides + 1
        faces += [(ring + k, ring + k + 1, centre)[::order] for k in range(sides)]
    text = lambda rows: " ".join(f"{v:.5f}" for row in rows for v in row)  # noqa: E731
    return (f'<mesh name="pillar" vertex="{text(vertices)}" texcoord="{text(uv)}" '
            f'face="{" ".join(str(i) for f in faces for i in f)}"/>')


WALL_SIDES = ("left", "right", "back")  # the walls' textured surfaces, one mesh each


def textured_geoms(n_pillars: int) -> str:
    """The walls' and pillars' visual copies (VISUAL_GROUP, no contacts): a mesh per wall side, which
    `CanyonWorld.load` writes per canyon (`wall_ribbon`), and a pillar mesh per pillar, parked."""
    walls = "".join(
        f'\n    <geom name="wall_{s}" type="mesh" mesh="wall_{s}" material="mat_{s}" group="{VISUAL_GROUP}" '
        f'contype="0" conaffinity="0"/>'
        for s in WALL_SIDES
    )
    return walls + "".join(
        f'\n    <geom name="obstaclev{i}" type="mesh" mesh="pillar" pos="0 {-10 - i} 0" '
        f'material="mat_pillars" group="{VISUAL_GROUP}" contype="0" conaffinity="0"/>'
        for i in range(n_pillars)
    )


def wall_ribbon(line: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A wall along the polyline `line` (n, 2) as a mesh: both faces of each piece, WALL_THICKNESS
    apart as its collision box's are, mitred where pieces meet (no gap), WALL_HEIGHT high, with texture
    coordinates in metres (arc length along the wall, height): the texture runs on unbroken from piece
    to piece. Each piece has its own vertices, so it is shaded flat. Returns vertices, texture
    coordinates and triangles."""
    d = np.diff(line, axis=0)
    length = np.linalg.norm(d, axis=1)
    normal = np.stack([-d[:, 1], d[:, 0]], axis=1) / length[:, None]
    # at each point the mitre: the mean of its pieces' normals, as long as keeps both faces t/2 off
    around = np.concatenate([normal[:1], normal]) + np.concatenate([normal, normal[-1:]])
    around /= np.linalg.norm(around, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", around, np.concatenate([normal, normal[-1:]]))
    offset = around * (WALL_THICKNESS / 2 / np.maximum(cos, 0.2))[:, None]
    arc = np.concatenate([[0.0], np.cumsum(length)])
    vertices, uv, faces = [], [], []
    for sign in (1.0, -1.0):  # the two faces, each with its own vertices (and so its own normals)
        for k in range(len(d)):
            base = len(vertices)
            for i in (k, k + 1):
                for z in (0.0, WALL_HEIGHT):
                    vertices.append((*(line[i] + sign * offset[i]), z))
                    uv.append((arc[i], z))
            # base: k low, k high, k+1 low, k+1 high; counter-clockwise seen from the face's side
            quad = [(base, base + 2, base + 3), (base, base + 3, base + 1)]
            faces += quad if sign < 0 else [t[::-1] for t in quad]
    return np.array(vertices), np.array(uv), np.array(faces)
