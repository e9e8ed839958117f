"""The floor labeller: depth bins from the camera and odometry alone, by where the floor ends.

The robot's camera looks level from a known height, so a floor pixel's row gives its distance. A small
convolutional net learns which pixels are free floor from the robot's own future footprint (its
rectangle at the next poses, from odometry, projected into the current frame: floor it drove over)
against pixels above the horizon (never floor). Per image column, the first non-floor pixel up from
the bottom is the obstacle's foot; its row, the camera's height and the column's bearing give the
range, resampled to the LiDAR's readings and bins (docs/design.md#camera-labels). Each frame's readings
then take the nearest of the readings of the frames of the last `memory_s` seconds, moved into it by
odometry (the canyons stand still): an obstacle the net loses as the robot closes in, once it fills the
bottom rows, stays where earlier frames saw it. No depth of any kind goes in: it may label the very
dataset it learnt from.

Its folder is a labeller folder (`depthq.labellers.labeller`), `name` "floor".
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image, ImageDraw
from torch import nn

from depthq.configio import from_dict, to_dict
from depthq.data.manifest import Dataset, RunEntry
from depthq.data.run import Run
from depthq.data.subsets import first_runs
from depthq.errors import DataError
from depthq.progress import Bar
from depthq.sim.mjcf import CameraConfig, RobotConfig
from depthq.sim.sensors import N_RAYS, BinConfig, depth_bins

BATCH = 32  # frames per forward pass
DILATIONS = (1, 2, 4, 8)
RECEPTIVE_RADIUS = sum(DILATIONS)  # pixels each side that a floor logit sees
CONTEXT_GRID = (2, 4)  # rows × columns of the context's colour grid
CONTEXT_BAND = 0.3  # the lowest fraction of a frame's rows that the context averages
CONTEXT = 3 * CONTEXT_GRID[0] * CONTEXT_GRID[1]
# A recording's frames may differ from the camera's size by this much in aspect ratio (rounding) and
# still be resized to it.
ASPECT_TOLERANCE = 0.02


@dataclass(frozen=True)
class Geometry:
    """What turns a floor boundary into ranges: the camera and robot of a dataset, at the net's scale."""

    camera: CameraConfig
    robot: RobotConfig
    bins: BinConfig
    scale: int  # the net sees frames reduced by this factor

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of a reduced frame."""
        return self.camera.height // self.scale, self.camera.width // self.scale

    @property
    def focal(self) -> float:
        """Focal length in reduced pixels (square pixels: MuJoCo's fovy follows the aspect ratio)."""
        return self.shape[1] / 2 / np.tan(np.deg2rad(self.camera.hfov_deg) / 2)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Floor points (P, 2) in the robot frame (x forward, y left, m) → (columns, rows) in reduced
        pixels, continuous (pixel i spans [i, i + 1)); points behind the camera come out NaN."""
        forward = points[:, 0] - self.robot.sensor_offset_x
        rows, cols = self.shape
        with np.errstate(divide="ignore", invalid="ignore"):
            forward = np.where(forward > 1e-3, forward, np.nan)
            u = cols / 2 - self.focal * points[:, 1] / forward
            v = rows / 2 + self.focal * self.camera.mount_height / forward
        return u, v

    def ranges(self, foot_rows: np.ndarray) -> np.ndarray:
        """Per frame, the obstacle's foot row in every column (N, columns), continuous → the LiDAR's
        readings from +first_bearing° down (N, n_readings), m, clipped at the bins' clip."""
        bearings, columns = self.bearing_columns()
        below = np.take(foot_rows, columns, axis=1) - self.shape[0] / 2  # rows under the horizon
        with np.errstate(divide="ignore"):
            forward = np.where(below > 0, self.focal * self.camera.mount_height / below, np.inf)
        return np.minimum(forward / np.cos(bearings), self.bins.clip).astype(np.float32)

    def bearing_columns(self) -> tuple[np.ndarray, np.ndarray]:
        """The LiDAR's readings' bearings (n_readings,), rad, from +first_bearing° down, and the reduced
        frame's column each falls in (n_readings,) int."""
        cols = self.shape[1]
        bearings = np.deg2rad(self.bins.first_bearing - np.arange(self.bins.n_readings))
        u = np.clip(cols / 2 - self.focal * np.tan(bearings), 0, cols - 1e-6)
        return bearings, u.astype(int)

    def bins_of(self, readings: np.ndarray) -> np.ndarray:
        """Readings (N, n_readings) → depth bins (N, n_bins): placed in a scan at their bearings, then
        binned as the LiDAR's (`depthq.sim.sensors.depth_bins`)."""
        scan = np.full((len(readings), N_RAYS), np.inf, np.float32)
        scan[:, (self.bins.first_bearing - np.arange(self.bins.n_readings)) % N_RAYS] = readings
        return depth_bins(scan, self.bins)


def remember(readings: np.ndarray, poses: np.ndarray, times: np.ndarray, geo: Geometry, memory_s: float
             ) -> np.ndarray:
    """Readings (N, n_readings) of a run's frames at `poses` (N, 3) and `times` (N,) s → each frame's
    readings fused with those of the frames up to `memory_s` s before it: every earlier obstacle point
    (a reading under the clip) moved into the frame's sensor frame by odometry, the nearest per reading."""
    fused = readings.copy()
    bearings = np.deg2rad(geo.bins.first_bearing - np.arange(geo.bins.n_readings))
    poses = poses.astype(np.float64)
    heading = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], axis=1)
    sensor = poses[:, :2] + geo.robot.sensor_offset_x * heading
    points = []  # each frame's obstacle points in the world, (x, y), computed once
    for k in range(len(readings)):
        seen = readings[k] < geo.bins.clip
        angle = poses[k, 2] + bearings[seen]
        points.append((sensor[k, 0] + readings[k, seen] * np.cos(angle),
                       sensor[k, 1] + readings[k, seen] * np.sin(angle)))
    for t in range(1, len(readings)):
        for k in range(t - 1, -1, -1):
            if times[t] - times[k] > memory_s + 1e-6:
                break
            dx, dy = points[k][0] - sensor[t, 0], points[k][1] - sensor[t, 1]
            bearing = (np.rad2deg(np.arctan2(dy, dx) - poses[t, 2]) + 180) % 360 - 180
            index = np.round(geo.bins.first_bearing - bearing).astype(int)
            inside = (index >= 0) & (index < geo.bins.n_readings)
            np.minimum.at(fused[t], index[inside], np.hypot(dx, dy)[inside].astype(np.float32))
    return fused


def geometry(env: dict[str, Any] | None, scale: int) -> Geometry:
    """A dataset's geometry from its env record (a robot's recording, resampled to the defaults: None)."""
    if env is None:
        return Geometry(CameraConfig(), RobotConfig(), BinConfig(), scale)
    world = env["world"]
    return Geometry(from_dict(CameraConfig, world["camera"]), from_dict(RobotConfig, world["robot"]),
                    from_dict(BinConfig, env["bins"]), scale)


def footprint(geo: Geometry, poses: np.ndarray, t: int, frames: int, nearest: float) -> np.ndarray:
    """Mask (rows, columns) bool of the floor the robot covers at poses t+1 … t+frames, seen from pose t:
    its rectangle at each pose, projected and filled; poses nearer than `nearest` m ahead are left out
    (the view under the camera's feet is not where obstacles are judged)."""
    x0, y0, yaw0 = poses[t]
    c, s = np.cos(yaw0), np.sin(yaw0)
    half_l, half_w = geo.robot.length / 2, geo.robot.width / 2
    corners = np.array([[half_l, half_w], [half_l, -half_w], [-half_l, -half_w], [-half_l, half_w]])
    corners[:, 0] += geo.robot.sensor_offset_x
    rows, cols = geo.shape
    image = Image.new("1", (cols, rows))
    draw = ImageDraw.Draw(image)
    for x, y, yaw in poses[t + 1 : t + 1 + frames]:
        cy, sy = np.cos(yaw), np.sin(yaw)
        world = np.stack([x + cy * corners[:, 0] - sy * corners[:, 1],
                          y + sy * corners[:, 0] + cy * corners[:, 1]], axis=1)
        dx, dy = world[:, 0] - x0, world[:, 1] - y0
        local = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)
        if (local[:, 0] - geo.robot.sensor_offset_x < nearest).any():
            continue
        u, v = geo.project(local)
        draw.polygon(list(zip(u.tolist(), v.tolist(), strict=True)), fill=1)
    return np.asarray(image, dtype=bool)


def reduce(frames: np.ndarray, geo: Geometry) -> np.ndarray:
    """uint8 frames (N, H, W, 3) → float32 (N, 3, rows, columns) in [0, 1] at `geo.shape`: box-averaged
    by the scale from the camera's size; frames of another size (a robot's recording) resized to it,
    if they have the camera's aspect ratio (else a DataError: their rows would give wrong distances)."""
    n, h, w, _ = frames.shape
    rows, cols = geo.shape
    scale = geo.scale
    if (h, w) != (geo.camera.height, geo.camera.width):
        if abs(w / h / (geo.camera.width / geo.camera.height) - 1) > ASPECT_TOLERANCE:
            raise DataError(f"frames of {w} × {h} pixels do not have the labeller's camera's aspect "
                            f"ratio ({geo.camera.width} × {geo.camera.height}): its rows would give wrong "
                            "distances")
        x = torch.from_numpy(np.ascontiguousarray(frames.transpose(0, 3, 1, 2), dtype=np.float32) / 255.0)
        x = F.interpolate(x, size=(rows, cols), mode="bilinear", antialias=True, align_corners=False)
        return x.numpy()
    x = frames[:, : rows * scale, : cols * scale].reshape(n, rows, scale, cols, scale, 3).mean(axis=(2, 4))
    return np.ascontiguousarray(x.transpose(0, 3, 1, 2), dtype=np.float32) / 255.0


class FloorNet(nn.Module):
    """Reduced frame (B, 3, H, W) and its context (B, CONTEXT) → floor logit (B, H, W): dilated 3×3
    convolutions, a receptive field of 2 × RECEPTIVE_RADIUS + 1 pixels, so a pixel is judged by the edges
    around it, not its colour alone; the context (`context_of`: the colours of the floor ahead, in the
    frame's lower band), where wanted, shifts the first layer, so that what floor looks like can differ
    canyon by canyon."""

    def __init__(self, width: int, context: bool = True) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        channels = 3
        for dilation in DILATIONS:
            layers += [nn.Conv2d(channels, width, 3, padding=dilation, dilation=dilation), nn.ReLU()]
            channels = width
        layers.append(nn.Conv2d(width, 1, 1))
        self.body = nn.Sequential(*layers)
        self.context = nn.Linear(CONTEXT, width) if context else None

    def forward(self, x: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        h = self.body[0](x - 0.5)  # the first convolution, before its ReLU
        if self.context is not None:
            h = h + self.context(context - 0.5)[:, :, None, None]
        return self.body[1:](h)[:, 0]


def context_of(frames: torch.Tensor) -> torch.Tensor:
    """Reduced whole frames (B, 3, H, W) → (B, CONTEXT): the mean colours of a 2 × 4 grid over the lowest
    CONTEXT_BAND of the rows (the floor just ahead, in most frames)."""
    band = frames[:, :, int(frames.shape[2] * (1 - CONTEXT_BAND)) :]
    return F.adaptive_avg_pool2d(band, CONTEXT_GRID).flatten(1)


def foot_rows(floor: np.ndarray, geo: Geometry, nearest: float) -> np.ndarray:
    """Floor probabilities (N, rows, columns) → per column the obstacle's foot row, continuous: going up
    from the row `nearest` m ahead, the first of two non-floor rows in a row; the horizon if none."""
    rows = floor.shape[1]
    horizon = rows / 2
    start = int(min(rows - 1, horizon + geo.focal * geo.camera.mount_height / nearest))
    stop = int(np.ceil(horizon))
    free = floor[:, stop : start + 1][:, ::-1] >= 0.5  # from `start` up to the horizon
    blocked = ~free[:, :-1] & ~free[:, 1:]
    first = np.where(blocked.any(axis=1), blocked.argmax(axis=1), free.shape[1])  # none: the horizon
    return (start + 1 - first).astype(np.float32)  # the foot: the lower edge of the first blocked row


def geometry_record(geo: Geometry) -> dict[str, Any]:
    """What a labeller folder records of the camera and robot it learnt with (the pixel noise aside)."""
    camera = {k: v for k, v in to_dict(geo.camera).items() if k != "noise_std"}
    return {"camera": camera, "robot": to_dict(geo.robot)}


def identity(config: Any, geometry: dict[str, Any], bins: dict[str, Any]) -> dict[str, Any]:
    """What fixes a floor labeller's output besides its weights (a LabellerConfig, `geometry_record`, the
    bins' config); `context` and `memory_s` named only when on, as records before them had none."""
    return {"method": "floor", "scale": config.scale, "nearest": config.nearest, "width": config.width,
            "geometry": geometry, "bins": bins, **({"context": True} if config.context else {}),
            **({"memory_s": config.memory_s} if config.memory_s else {})}


def env_of(record: dict[str, Any], bins: dict[str, Any]) -> dict[str, Any]:
    """An env record holding a labeller folder's geometry and bins (for `geometry`)."""
    return {"world": record, "bins": bins}


class ReadingsEstimate:
    """A run → bins (N, n_bins) float32 from each frame's own LiDAR-like readings (`readings`, a camera
    labeller's own), fused by the memory and binned: what the floor and monodepth labellers share."""

    geo: Geometry
    memory_s: float

    def __call__(self, run: Run) -> np.ndarray:
        return self.bins(self.readings(run.images), run, self.memory_s)

    def bins(self, readings: np.ndarray, run: Run, memory_s: float) -> np.ndarray:
        """A run's own readings → its bins (N, n_bins) float32, with a memory of `memory_s` s (0: none)."""
        if memory_s:
            readings = remember(readings, run.poses, run.times, self.geo, memory_s)
        return self.geo.bins_of(readings)

    def readings(self, frames: np.ndarray) -> np.ndarray:
        """uint8 frames (N, H, W, 3) → each frame's own readings (N, n_readings), m."""
        raise NotImplementedError


class FloorEstimate(ReadingsEstimate):
    """A run → bins (N, n_bins) float32: floor net, foot rows, readings, the memory, bins."""

    def __init__(self, net: FloorNet, geo: Geometry, nearest: float, memory_s: float = 0.0) -> None:
        self.net, self.geo, self.nearest, self.memory_s = net, geo, nearest, memory_s
        # The net sees the rows from a receptive field above the horizon down: those above are no floor.
        self.top = max(0, int(geo.shape[0] / 2) - RECEPTIVE_RADIUS - 1)

    @torch.inference_mode()
    def readings(self, frames: np.ndarray) -> np.ndarray:
        """uint8 frames (N, H, W, 3) → each frame's own readings (N, n_readings), m."""
        out = []
        for i in range(0, len(frames), BATCH):
            x = torch.from_numpy(reduce(frames[i : i + BATCH], self.geo))
            p = np.zeros((len(x), *self.geo.shape), np.float32)
            p[:, self.top :] = torch.sigmoid(self.net(x[:, :, self.top :], context_of(x))).numpy()
            out.append(self.geo.ranges(foot_rows(p, self.geo, self.nearest)))
        return np.concatenate(out)


def _pool(dataset: Dataset, entries: list[RunEntry], geo: Geometry, config: Any, rng: np.random.Generator,
          progress: bool) -> tuple[np.ndarray, np.ndarray]:
    """Reduced frames (F, 3, rows, cols) float16 and their footprint masks (F, rows, cols) of up to
    `config.pool_frames` random frames of each run whose future footprint is in view."""
    images, masks = [], []
    for entry in Bar(entries, desc="floor pool", unit="run", disable=not progress):
        run = dataset.read_run(entry, images=True)
        n = len(run.poses) - 1
        for t in rng.choice(n, size=min(config.pool_frames, n), replace=False) if n > 0 else ():
            mask = footprint(geo, run.poses, int(t), config.lookahead, config.nearest)
            if mask.any():
                images.append(reduce(run.images[t : t + 1], geo)[0].astype(np.float16))
                masks.append(mask)
    if not images:
        raise DataError(f"{dataset.root}: no frame sees the robot's future footprint to learn the floor from")
    return np.stack(images), np.stack(masks)


def _loss(net: FloorNet, images: np.ndarray, masks: np.ndarray, above: torch.Tensor,
          device: torch.device) -> torch.Tensor:
    """Footprint pixels are floor, pixels above the horizon are not: the mean of both classes' BCE."""
    x = torch.from_numpy(images.astype(np.float32)).to(device)
    logit = net(x, context_of(x))
    floor_ = torch.from_numpy(masks).to(device)
    return (F.softplus(-logit[floor_]).mean() + F.softplus(logit[:, above]).mean()) / 2


def train(dataset: Dataset, geo: Geometry, config: Any, progress: bool, device: torch.device
          ) -> tuple[FloorNet, list[float], float]:
    """The floor net learnt on `dataset`'s frames and poses (a LabellerConfig): (net, losses, val loss)."""
    rng = np.random.default_rng(config.seed)
    pooled = first_runs(dataset, "train", config.pool_runs, config.pool == "every_look")
    train_pool = _pool(dataset, pooled, geo, config, rng, progress)
    val_pool = _pool(dataset, dataset.entries("val"), geo, replace(config, pool_frames=1), rng, False)
    above = torch.zeros(geo.shape, dtype=torch.bool, device=device)
    above[: int(geo.shape[0] / 2) - 1] = True
    net = FloorNet(config.width, config.context).to(device)
    optimizer = torch.optim.Adam(net.parameters(), lr=config.lr)
    losses = []
    for _ in Bar(range(config.steps), desc="train floor", unit="step", disable=not progress):
        idx = rng.choice(len(train_pool[0]), size=config.batch_size)
        loss = _loss(net, train_pool[0][idx], train_pool[1][idx], above, device)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    with torch.no_grad():
        images, masks = val_pool
        val = np.mean([_loss(net, images[i : i + BATCH], masks[i : i + BATCH], above, device).item()
                       for i in range(0, len(images), BATCH)])
    return net.cpu().eval(), losses, float(val)
