"""The physics side (dm_control's "physics"): MuJoCo model and data, the canyon written into the
walls, velocity-controlled driving, the camera and the LiDAR. No rewards, no termination here."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import mujoco
import numpy as np

from depthq.configio import OMIT_DEFAULT
from depthq.errors import ConfigError
from depthq.sim.camera import OffscreenCamera
from depthq.sim.camera_model import ImagingConfig, RobotCamera, noise_table
from depthq.sim.canyon import FAMILIES, PAPER, Canyon, CanyonConfig
from depthq.sim.look import FLAT, SURFACES, CanyonLook, check_look, draw_canyon_look, imaging, is_textured
from depthq.sim.mjcf import (
    ROBOT_GROUP,
    VISUAL_GROUP,
    WALL_GROUP,
    WALL_HEIGHT,
    WALL_SIDES,
    WALL_THICKNESS,
    CameraConfig,
    RobotConfig,
    build_mjcf,
    wall_ribbon,
)
from depthq.sim.sensors import LidarConfig, finish_scan, ray_directions

NOMINAL_DECISION_HZ = 10.0  # the TurtleBot3 camera's nominal frame rate (docs/design.md#decision-rate)
DEFAULT_DECISION_HZ = 4.0  # calibrated against Table II's frames per run (docs/calibration.md)
TURTLEBOT3_MAX_YAW_RATE = 2.84  # rad/s, the Burger's maximum angular velocity


@dataclass(frozen=True)
class WorldConfig:
    """Everything physical: canyon generator, robot, sensors, rates and look."""

    canyon: CanyonConfig = field(default_factory=CanyonConfig)  # the canyon generator
    robot: RobotConfig = field(default_factory=RobotConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    speed: float = 0.5  # forward speed, m/s, constant
    max_yaw_rate: float = 1.0  # rad/s; commanded yaw rates are clipped to ±this
    # Decisions (camera frames) per second, one decision per frame (docs/calibration.md). The
    # original camera is nominally 10 Hz, but the rate at which its frames were really saved is
    # unknown; DEFAULT_DECISION_HZ is calibrated to Table II.
    decision_hz: float = DEFAULT_DECISION_HZ
    physics_dt: float = 0.005  # MuJoCo's time step, s; a decision's period is a whole number of them
    # How the canyons look (docs/design.md#looks): flat, colours, textured, heldout, broad or a folder of
    # images; a family's own look is its default (the paper's flat, the hard family's colours).
    look: str = FLAT
    # The robot camera's imaging chain (auto-exposure, white balance, vignetting, motion blur, JPEG).
    imaging: ImagingConfig = field(default_factory=ImagingConfig, metadata=OMIT_DEFAULT)
    # The sun casts shadows in the textured looks (costly on a software renderer: docs/benchmarks.md).
    shadows: bool = field(default=False, metadata=OMIT_DEFAULT)
    # The canyon family whose canyons `canyon` generates: paper or hard (`depthq.sim.canyon.FAMILIES`).
    family: Literal[tuple(FAMILIES)] = field(default=PAPER, metadata=OMIT_DEFAULT)  # type: ignore[valid-type]

    def __post_init__(self) -> None:
        if not self.speed > 0:
            raise ConfigError(f"speed must be > 0 m/s, got {self.speed}")
        if not self.max_yaw_rate > 0:
            raise ConfigError(f"max_yaw_rate must be > 0, got {self.max_yaw_rate}")
        if not self.decision_hz > 0:
            raise ConfigError(f"decision_hz must be > 0, got {self.decision_hz}")
        if not 0 < self.physics_dt <= 0.005:
            raise ConfigError(f"physics_dt must lie in (0, 0.005] s, got {self.physics_dt}")
        substeps = 1.0 / (self.decision_hz * self.physics_dt)
        if substeps < 0.5 or abs(substeps - round(substeps)) > 0.05:
            raise ConfigError(
                f"1/decision_hz must be a multiple of physics_dt ({self.physics_dt} s), got decision_hz "
                f"{self.decision_hz} (a period of {1 / self.decision_hz:.4f} s)"
            )
        check_look(self.look)
        if self.family not in FAMILIES:
            raise ConfigError(f"unknown canyon family {self.family!r}; expected one of {sorted(FAMILIES)}")

    @property
    def textured(self) -> bool:
        """Whether the look draws image textures (and the camera model is on by default)."""
        return is_textured(self.look)

    @property
    def substeps(self) -> int:
        return round(1.0 / (self.decision_hz * self.physics_dt))

    @property
    def period(self) -> float:
        """Seconds between two decisions (camera frames): a whole number of physics steps."""
        return self.substeps * self.physics_dt


def world_for(world: WorldConfig, family: str) -> WorldConfig:
    """`world` for another canyon family: that family's generator and look, the same robot, sensors
    and rates. A world already of `family` is returned as it is (its canyon config may be a variant)."""
    if family not in FAMILIES:
        raise ConfigError(f"unknown canyon family {family!r}; expected one of {sorted(FAMILIES)}")
    if world.family == family:
        return world
    spec = FAMILIES[family]
    return replace(world, canyon=spec.canyon, look=spec.look, family=family)


_TEXTURES = tuple(f"tex_{s}" for s in SURFACES)
_SHELL = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL  # a wall's mesh: its inertia from its surface


class CanyonWorld:
    """MuJoCo world: `load` a canyon, `place` the robot, `advance`, sense (camera, LiDAR).

    The MJCF is parsed once into an `MjSpec`; `load` writes the canyon's walls into it and compiles
    a fresh model (< 1 ms), so collision and ray-cast acceleration structures are always exact.
    """

    def __init__(self, config: WorldConfig = WorldConfig(), render: bool = True) -> None:
        self.config = config
        xml = build_mjcf(config.canyon, config.camera, config.robot, config.lidar, config.physics_dt,
                         textured=config.textured, shadows=config.shadows)
        self._spec = mujoco.MjSpec.from_string(xml)
        self._walls = [self._spec.geom(f"wall{i}") for i in range(self._n_walls)]
        self._obstacles = [self._spec.geom(f"obstacle{i}") for i in range(config.canyon.obstacles.count)]
        self._parked = [np.array(g.pos) for g in self._obstacles]
        self._default_wall_rgba = np.array(self._walls[0].rgba)
        self._default_ground_rgba = np.array(self._spec.geom("ground").rgba)
        self._default_pillar_rgba = np.array(self._obstacles[0].rgba) if self._obstacles else None
        self._default_sun_dir = np.array(self._spec.light("sun").dir)
        if config.textured:
            self._visual_pillars = [self._spec.geom(f"obstaclev{i}") for i in range(len(self._obstacles))]
        self.model = self._spec.compile()
        self.data = mujoco.MjData(self.model)
        self._robot_body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "robot")
        self._lidar_site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, "lidar")
        self._rays = np.zeros((config.lidar.n_rays, 3))
        self._rays[:, :2] = ray_directions(config.lidar.n_rays)
        self._ray_geom = np.zeros(config.lidar.n_rays, np.int32)
        self._ray_dist = np.zeros(config.lidar.n_rays)
        self.last_raycast = np.full(config.lidar.n_rays, -1.0)  # the noise-free distances of the last scan
        self._geomgroup = np.zeros(6, np.uint8)
        self._geomgroup[WALL_GROUP] = 1
        self._noise = noise_table(255.0 * config.camera.noise_std)
        cam = config.camera
        # The robot's own body is hidden from its camera, as on the real robot (camera above the chassis);
        # in a textured look so are the walls and pillars, whose textured copies it sees instead.
        hidden, shown = ((ROBOT_GROUP, WALL_GROUP), (VISUAL_GROUP,)) if config.textured else (
            (ROBOT_GROUP,), ())
        self._eye = OffscreenCamera(self.model, cam.width, cam.height, hidden, shown) if render else None
        self.canyon: Canyon | None = None
        self.robot_camera: RobotCamera | None = None  # this run's camera model (`start_run`)

    @property
    def _n_walls(self) -> int:
        return 2 * (self.config.canyon.n_segments + 1) + 1

    def load(self, canyon: Canyon, appearance_rng: np.random.Generator | None = None) -> None:
        """Build the world of one canyon: wall boxes along its polylines, colours, light."""
        seg = canyon.segments()
        if len(seg) != self._n_walls:
            raise ConfigError(f"canyon has {len(seg)} wall pieces, the world was built for {self._n_walls}")
        a, b = seg[:, 0], seg[:, 1]
        half = np.linalg.norm(b - a, axis=1) / 2
        yaw = np.arctan2(b[:, 1] - a[:, 1], b[:, 0] - a[:, 0])
        mid = (a + b) / 2
        textured = self.config.textured
        if textured:
            rng = appearance_rng or np.random.default_rng(canyon.id.appearance_seed)
            look = draw_canyon_look(self.config.look, rng)
            rgba, pillar_rgba = self._lit(look)
        else:
            rgba, pillar_rgba = self._appearance(appearance_rng)
        for k, geom in enumerate(self._walls):
            geom.pos = (mid[k, 0], mid[k, 1], WALL_HEIGHT / 2)
            geom.quat = (math.cos(yaw[k] / 2), 0.0, 0.0, math.sin(yaw[k] / 2))
            geom.size = (half[k], WALL_THICKNESS / 2, WALL_HEIGHT / 2)
            geom.rgba = rgba[k]
        if textured:  # each side's visual copy: one mesh along the whole wall
            for side, line in zip(WALL_SIDES, (canyon.left, canyon.right, canyon.back), strict=True):
                vertices, uv, faces = wall_ribbon(line)
                # A new mesh each time: MuJoCo 4.0 crashes recompiling a mesh whose vertices were replaced.
                self._spec.delete(self._spec.mesh(f"wall_{side}"))
                mesh = self._spec.add_mesh(name=f"wall_{side}", inertia=_SHELL)
                mesh.uservert = vertices.reshape(-1).tolist()
                mesh.usertexcoord = uv.reshape(-1).tolist()
                mesh.userface = faces.reshape(-1).tolist()
        if len(canyon.obstacles) > len(self._obstacles):
            raise ConfigError(
                f"canyon has {len(canyon.obstacles)} pillars, the world was built for {len(self._obstacles)}"
            )
        for k, geom in enumerate(self._obstacles):  # pillars the canyon left out stay parked
            placed = k < len(canyon.obstacles)
            geom.pos = (*canyon.obstacles[k, :2], geom.pos[2]) if placed else self._parked[k]
            geom.rgba = pillar_rgba
            if textured:
                self._visual_pillars[k].pos = geom.pos
        self.model = self._spec.compile()
        self.data = mujoco.MjData(self.model)
        self.canyon = canyon
        if textured:
            self._paint(look)

    def _lit(self, look: CanyonLook) -> tuple[np.ndarray, np.ndarray]:
        """A textured look's sun and sky, set in the spec before it compiles; the (hidden) collision
        geoms keep the default colours."""
        sun, sky = self._spec.light("sun"), self._spec.texture("sky")
        sun.dir, sun.diffuse = look.sun_dir, look.sun_diffuse
        sky.rgb1, sky.rgb2 = look.sky
        return np.tile(self._default_wall_rgba, (self._n_walls, 1)), self._default_pillar_rgba

    def _paint(self, look: CanyonLook) -> None:
        """Write a textured look's pixels into the compiled model and upload them, with the sky and the
        walls' meshes, to the renderer (its context was made from the first model); set the ambient light."""
        m = self.model
        m.vis.headlight.ambient[:] = look.ambient
        m.vis.headlight.diffuse[:] = 0.1
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TEXTURE, name) for name in ("sky", *_TEXTURES)]
        for name, tex in zip(SURFACES, ids[1:], strict=True):
            pixels = look.textures[name]
            adr = m.tex_adr[tex]
            m.tex_data[adr : adr + pixels.size] = pixels.reshape(-1)
        if self._eye is not None:
            meshes = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_MESH, f"wall_{side}") for side in WALL_SIDES]
            self._eye.upload(m, ids, meshes)

    def _appearance(self, rng: np.random.Generator | None) -> tuple[np.ndarray, np.ndarray]:
        """Wall colours (and, randomised, ground colour and sun direction) for the next canyon."""
        ground, sun = self._spec.geom("ground"), self._spec.light("sun")
        rgba = np.tile(self._default_wall_rgba, (self._n_walls, 1))
        pillar = self._default_pillar_rgba
        if self.config.look == FLAT or rng is None:
            ground.rgba, sun.dir = self._default_ground_rgba, self._default_sun_dir
            return rgba, pillar
        # Domain randomisation: one colour per wall side, a ground colour and a sun direction per canyon.
        n_side = self.config.canyon.n_segments + 1
        side_colours = rng.uniform(0.15, 0.95, size=(3, 3))
        rgba[:n_side, :3] = side_colours[0]
        rgba[n_side : 2 * n_side, :3] = side_colours[1]
        rgba[-1, :3] = side_colours[2]
        rgba[:, :3] = np.clip(rgba[:, :3] + rng.uniform(-0.05, 0.05, size=(self._n_walls, 3)), 0, 1)
        ground.rgba = (*rng.uniform(0.1, 0.7, size=3), 1.0)
        d = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), -rng.uniform(0.5, 1.5)])
        sun.dir = d / np.linalg.norm(d)
        if self._obstacles:  # drawn last: a canyon without pillars looks as before
            pillar = np.array([*rng.uniform(0.1, 0.9, size=3), 1.0])
        return rgba, pillar

    def place(self, x: float, y: float, yaw: float) -> None:
        """Put the robot at a pose, at rest."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = (x, y, yaw)
        mujoco.mj_forward(self.model, self.data)

    @property
    def pose(self) -> np.ndarray:
        """(x, y, yaw) of the axle centre."""
        return self.data.qpos[:3].copy()

    def advance(self, yaw_rate: float) -> bool:
        """Drive one decision period at constant speed and `yaw_rate`; True on contact with a wall.

        Velocity control: the body's planar velocity is set every physics step (diff drive without
        slip), MuJoCo integrates it and detects contacts. The run stops at the first contact.
        """
        return self.drive(self.config.speed, yaw_rate, self.config.substeps)

    def drive(self, speed: float, yaw_rate: float, steps: int = 1) -> bool:
        """`steps` physics steps at `speed` (m/s, forward) and `yaw_rate` as `advance` drives them: a
        robot moved by its velocity commands (`depthq ros sim`); True on contact with a wall."""
        m, d = self.model, self.data
        for _ in range(steps):
            yaw = d.qpos[2]
            d.qvel[:] = (speed * math.cos(yaw), speed * math.sin(yaw), yaw_rate)
            mujoco.mj_step(m, d)
            if d.ncon:
                return True
        return False

    def sensor_origin(self) -> np.ndarray:
        return self.data.site_xpos[self._lidar_site].copy()

    def raycast(self) -> np.ndarray:
        """Noise-free LiDAR distances to the walls (−1 where nothing within range)."""
        yaw = self.data.qpos[2]
        c, s = math.cos(yaw), math.sin(yaw)
        rays = self._rays.copy()
        rays[:, 0] = c * self._rays[:, 0] - s * self._rays[:, 1]
        rays[:, 1] = s * self._rays[:, 0] + c * self._rays[:, 1]
        mujoco.mj_multiRay(
            self.model,
            self.data,
            self.data.site_xpos[self._lidar_site],
            rays.reshape(-1),
            self._geomgroup,
            1,
            self._robot_body,
            self._ray_geom,
            self._ray_dist,
            None,
            len(rays),
            self.config.lidar.range_max + 1.0,
        )
        return self._ray_dist.copy()

    def scan(self, rng: np.random.Generator) -> np.ndarray:
        """A LiDAR reading: ray cast, Gaussian noise, range limits (see `sensors.finish_scan`)."""
        self.last_raycast = self.raycast()
        return finish_scan(self.last_raycast, self.config.lidar, rng)

    def render(self) -> np.ndarray:
        """The camera frame without noise, uint8 (height, width, 3). The returned array is reused."""
        if self._eye is None:
            raise RuntimeError("this world was built with render=False")
        return self._eye.render(self.model, self.data, "eye")

    def start_run(self, rng: np.random.Generator) -> None:
        """Draw a run's camera (`depthq.sim.camera_model`) when the look has one; nothing drawn otherwise."""
        cam, ranges = self.config.camera, imaging(self.config.look, self.config.imaging)
        if not ranges.on(self.config.textured):
            self.robot_camera = None
            return
        own = np.random.default_rng(rng.integers(2**63))
        self.robot_camera = RobotCamera(ranges, cam.width, cam.height, cam.hfov_deg, cam.noise_std, own)

    def image(self, rng: np.random.Generator) -> np.ndarray:
        """The camera frame: the render with Gaussian pixel noise (σ = camera.noise_std of full scale),
        through this run's camera model (`start_run`) when there is one."""
        frame = self.render()
        if self.robot_camera is None:
            noise = self._noise[rng.integers(0, 256, size=frame.shape, dtype=np.uint8)]
            return np.clip(frame.astype(np.int16) + noise, 0, 255).astype(np.uint8)
        return self.robot_camera.take(frame, float(self.data.qvel[2]), rng)

    def close(self) -> None:
        if self._eye is not None:
            self._eye.close()
            self._eye = None
