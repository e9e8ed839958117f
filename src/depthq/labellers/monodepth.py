"""The monodepth labeller: depth bins from a depth network learnt by photometric reprojection.

Self-supervised monocular depth as Monodepth2 (Godard et al., 2019) learns it: a small encoder–decoder
predicts a frame's per-pixel depth; with that depth, the camera's intrinsics and the camera's motion
between consecutive frames of the same run, each neighbouring frame (t − 1, t + 1) is warped into
frame t, and the depth is whatever makes the warped frames look like frame t. The motion comes from
the recorded odometry, not from a pose network as in Monodepth2, so the depth is metric: no LiDAR or
depth of any kind goes in, and it may label the very dataset it learnt from (as the floor labeller).
The loss is Monodepth2's: 0.85 · (1 − SSIM) / 2 + 0.15 · L1 per pixel, the minimum over the two
neighbours (a pixel hidden in one, or out of its view, is seen in the other), auto-masking (a pixel
whose unwarped neighbour already matches better than the warped one, something that moves with the
camera or shows no texture, counts with that unwarped error, which no depth changes: it is left out),
and an edge-aware smoothness on the mean-normalised disparity, over four output scales upsampled to
the frame's size. Two departures, both for the canyons' flat-shaded, untextured faces, where only edges
say anything: the net's depths reach beyond the bins' clip (`max_depth`), as the floor and the walls
down the canyon do, which capped at the clip would warp wrongly; and it starts far (START_DEPTH), not
near. Reading the bins: the camera is level, so the horizon rows of a bearing's column see what the
LiDAR's ray of that bearing hits; their depth gives the range (docs/design.md#camera-labels), then the
floor labeller's memory and bins.

Kornia does the projective geometry (warping by depth), SSIM and the smoothness term.

Its folder is a labeller folder (`depthq.labellers.labeller`), `name` "monodepth".
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Literal

import kornia
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from depthq.data.manifest import Dataset, RunEntry
from depthq.data.subsets import first_runs
from depthq.errors import DataError
from depthq.labellers.floor import BATCH, Geometry, ReadingsEstimate, reduce
from depthq.progress import Bar

# The depth net's channels per level, in multiples of its width: its encoder halves the frame's size at
# each level, and each decoder level gives a disparity, at 1, 1/2, 1/4, 1/8 of the size (Monodepth2's).
LEVELS = (1, 2, 4, 4)
SCALES = len(LEVELS)
SSIM_WEIGHT = 0.85  # of (1 − SSIM) / 2 against 0.15 of L1 in the photometric error (Monodepth2's)
SSIM_WINDOW = 3  # pixels: SSIM's window (Monodepth2's 3 × 3)
# m: a neighbour counts as moved from frame t when the camera is this far from where it was at t (a
# robot standing still shows no parallax: its frames teach no depth).
MIN_MOVE = 0.02
# Rows each side of the horizon whose median depth is a column's reading: the camera is level, so these
# rows see what the LiDAR's level ray sees (walls and pillars are vertical; the floor in them is at
# least f · 0.24 / HORIZON_ROWS m away: 4.8 m at scale 4, beyond the clip). The median, not the
# minimum: a photometric depth is noisy pixel by pixel, and one wrong pixel would set the reading;
# obstacles that earlier frames saw nearer are kept by the memory, which takes the nearest.
HORIZON_ROWS = 2
# m: the depth the net starts at everywhere. Far, not Monodepth2's sigmoid(0) (0.2 m here): in the
# canyons' flat-shaded faces the photometric error has a gradient only within a pixel of an edge, and
# from a near start the net can settle with every horizon beyond the clip (docs/design.md#camera-labels).
START_DEPTH = 3.0
# How the photometric loss brings a neighbouring frame to the target's brightness before comparing them
# (`compensate`): not at all, a gain per colour channel, or a gain and a bias per colour channel.
Brightness = Literal["none", "gain", "affine"]
EPS = 1e-6  # a mean or variance below this is taken as this in `compensate`


class DepthNet(nn.Module):
    """Reduced frame (B, 3, H, W) in [0, 1] → disparities in (0, 1) (sigmoid), one per decoder level,
    finest first: (B, 1, H, W), (B, 1, H/2, W/2), …; a U-Net of 3 × 3 convolutions (ELU, reflection
    padding), `width` × LEVELS channels at 1/2 … 1/16 of the frame's size, and back. `start`: the
    disparity its heads give at first (their bias; loaded weights replace it)."""

    def __init__(self, width: int, start: float = 0.5) -> None:
        super().__init__()
        channels = [width * m for m in LEVELS]
        self.encoder = nn.ModuleList()
        previous = 3
        for c in channels:
            self.encoder.append(nn.Sequential(_conv(previous, c, stride=2), _conv(c, c)))
            previous = c
        self.decoder, self.heads = nn.ModuleList(), nn.ModuleList()
        # Each decoder level, coarsest first, concatenates an encoder level's output (the frame's, last)
        # and gives as many channels (half the width at the frame's size).
        skips = [3, *channels[:-1]][::-1]
        for skip in skips:
            c = max(skip, width // 2)
            self.decoder.append(_conv(previous + skip, c))
            self.heads.append(nn.Conv2d(c, 1, 3, padding=1, padding_mode="reflect"))
            nn.init.constant_(self.heads[-1].bias, float(np.log(start / (1 - start))))
            previous = c

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        features = [x - 0.5]
        for block in self.encoder:
            features.append(block(features[-1]))
        h = features.pop()
        outputs = []
        for block, head in zip(self.decoder, self.heads, strict=True):
            skip = features.pop()
            h = block(torch.cat([F.interpolate(h, size=skip.shape[-2:], mode="nearest"), skip], dim=1))
            outputs.append(torch.sigmoid(head(h)))
        return outputs[::-1]


def _conv(c_in: int, c_out: int, stride: int = 1) -> nn.Sequential:
    conv = nn.Conv2d(c_in, c_out, 3, stride=stride, padding=1, padding_mode="reflect")
    return nn.Sequential(conv, nn.ELU())


def disparity_of(depth: float, min_depth: float, max_depth: float) -> float:
    """The sigmoid's output that `depth_of` maps to `depth`."""
    low, high = 1 / max_depth, 1 / min_depth
    return (1 / depth - low) / (high - low)


def depth_of(disparity: torch.Tensor, min_depth: float, max_depth: float) -> torch.Tensor:
    """A sigmoid's output in (0, 1) → depth in (min_depth, max_depth), linear in inverse depth
    (Monodepth2's `disp_to_depth`)."""
    low, high = 1 / max_depth, 1 / min_depth
    return 1 / (low + (high - low) * disparity)


def intrinsics(geo: Geometry) -> torch.Tensor:
    """The reduced frame's camera matrix (3, 3): focal length `geo.focal`, principal point at the centre
    (pixel centres at integers, as kornia's grids: the centre of W columns is (W − 1) / 2)."""
    rows, cols = geo.shape
    return torch.tensor([[geo.focal, 0, (cols - 1) / 2], [0, geo.focal, (rows - 1) / 2], [0, 0, 1]],
                        dtype=torch.float32)


def camera_poses(poses: np.ndarray, geo: Geometry) -> np.ndarray:
    """Robot poses (N, 3) x, y, yaw in the world → the camera's (N, 4, 4), world from camera, in the
    camera axes of kornia and OpenCV: x right (the robot's −y), y down, z forward (the robot's x); the
    camera `sensor_offset_x` ahead of the axle, `mount_height` up, level."""
    x, y, yaw = np.asarray(poses, np.float64).T
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros((len(x), 4, 4))
    out[:, :3, 0] = np.stack([s, -c, 0 * c], axis=1)  # right
    out[:, 2, 1] = -1.0  # down
    out[:, :3, 2] = np.stack([c, s, 0 * c], axis=1)  # forward
    offset, height = geo.robot.sensor_offset_x, geo.camera.mount_height
    out[:, :3, 3] = np.stack([x + offset * c, y + offset * s, np.full_like(x, height)], axis=1)
    out[:, 3, 3] = 1.0
    return out


def source_from_target(poses: np.ndarray, target: int, sources: tuple[int, ...], geo: Geometry
                       ) -> np.ndarray:
    """(len(sources), 4, 4) float32: points in the camera frame at pose `target` → the camera frame at
    each source pose (kornia's `src_trans_dst`), from a run's robot poses (N, 3)."""
    cameras = camera_poses(poses[[target, *sources]], geo)
    return (np.linalg.inv(cameras[1:]) @ cameras[0]).astype(np.float32)


def photometric(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Frames (B, 3, H, W) → per-pixel error (B, 1, H, W): SSIM_WEIGHT · (1 − SSIM) / 2 + the rest · L1."""
    ssim = kornia.losses.ssim_loss(a, b, SSIM_WINDOW, reduction="none").mean(1, keepdim=True)
    return SSIM_WEIGHT * ssim + (1 - SSIM_WEIGHT) * (a - b).abs().mean(1, keepdim=True)


def compensate(source: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, brightness: Brightness
               ) -> torch.Tensor:
    """A (warped) source frame (B, 3, H, W) brought to the target's brightness per frame and colour
    channel: `source` · a + b with a, b the least-squares fit of the target over the `valid` pixels
    (B, 1, H, W) ("affine"), a = the ratio of their means and b = 0 ("gain"), or `source` as it is
    ("none"). The fit is detached: it corrects the pair's exposure and white balance, and the depth is
    learnt from what the correction leaves."""
    if brightness == "none":
        return source
    with torch.no_grad():
        weight = valid.to(source.dtype)
        count = weight.sum((2, 3), keepdim=True).clamp_min(1.0)
        mean_s = (source * weight).sum((2, 3), keepdim=True) / count
        mean_t = (target * weight).sum((2, 3), keepdim=True) / count
        if brightness == "gain":
            gain, bias = mean_t / mean_s.clamp_min(EPS), torch.zeros_like(mean_t)
        else:
            centred = (source - mean_s) * weight
            variance = (centred**2).sum((2, 3), keepdim=True)
            gain = (centred * (target - mean_t)).sum((2, 3), keepdim=True) / variance.clamp_min(EPS)
            bias = mean_t - gain * mean_s
    return source * gain + bias


def loss(net: DepthNet, frames: torch.Tensor, transforms: torch.Tensor, camera: torch.Tensor,
         depth_range: tuple[float, float], smoothness: float, brightness: Brightness = "none"
         ) -> torch.Tensor:
    """Frame triplets (B, 3, 3, H, W) (t − 1, t, t + 1) and `source_from_target` of each (B, 2, 4, 4) →
    Monodepth2's loss of frame t's predicted depth: per scale, the photometric error of the warped
    neighbours, each brought to frame t's brightness (`compensate`, over the pixels it sees), their
    per-pixel minimum, auto-masked by the unwarped neighbours' minimum (compensated alike, over every
    pixel), plus the edge-aware smoothness of the mean-normalised disparity (weight `smoothness` /
    2^scale); the mean over the scales."""
    target, sources = frames[:, 1], (frames[:, 0], frames[:, 2])
    size, matrix = target.shape[-2:], camera.expand(len(target), 3, 3)
    everywhere = torch.ones_like(target[:, :1])
    still = torch.minimum(*(photometric(compensate(s, target, everywhere, brightness), target)
                            for s in sources))
    # Each source carries a channel of ones through the warp: where it comes out whole, the pixel was
    # in the source's view (out of view, the warp gives zeros).
    sources = tuple(torch.cat([s, everywhere], dim=1) for s in sources)
    total = frames.new_zeros(())
    for scale, disparity in enumerate(net(target)):
        depth = depth_of(F.interpolate(disparity, size=size, mode="bilinear", align_corners=False),
                         *depth_range)
        errors = []
        for k, s in enumerate(sources):
            warped = kornia.geometry.depth.warp_frame_depth(s, depth, transforms[:, k], matrix)
            seen = warped[:, 3:] > 1 - 1e-3
            errors.append(photometric(compensate(warped[:, :3], target, seen, brightness), target))
        total = total + torch.minimum(torch.minimum(*errors), still).mean()
        image = F.interpolate(target, size=disparity.shape[-2:], mode="area")
        normalised = disparity / (disparity.mean((2, 3), keepdim=True) + 1e-7)
        total = total + smoothness / 2**scale * kornia.losses.inverse_depth_smoothness_loss(normalised, image)
    return total / SCALES


def horizon_depths(depth: np.ndarray, geo: Geometry) -> np.ndarray:
    """Depth (N, rows, columns) of reduced frames → the LiDAR's readings (N, n_readings), m: per bearing,
    the median depth of its column's horizon rows, along the ray (z / cos(bearing)), clipped."""
    rows = geo.shape[0]
    band = slice(int(rows / 2) - HORIZON_ROWS, int(np.ceil(rows / 2)) + HORIZON_ROWS)
    bearings, columns = geo.bearing_columns()
    z = np.median(depth[:, band][:, :, columns], axis=1)
    return np.minimum(z / np.cos(bearings), geo.bins.clip).astype(np.float32)


class MonodepthEstimate(ReadingsEstimate):
    """A run → bins (N, n_bins) float32: depth net, horizon depths, the memory, bins."""

    def __init__(self, net: DepthNet, geo: Geometry, depth_range: tuple[float, float], memory_s: float
                 ) -> None:
        self.net, self.geo, self.depth_range, self.memory_s = net, geo, depth_range, memory_s

    @torch.inference_mode()
    def readings(self, frames: np.ndarray) -> np.ndarray:
        """uint8 frames (N, H, W, 3) → each frame's own readings (N, n_readings), m."""
        out = []
        for i in range(0, len(frames), BATCH):
            disparity = self.net(torch.from_numpy(reduce(frames[i : i + BATCH], self.geo)))[0]
            depth = depth_of(disparity[:, 0], *self.depth_range).numpy()
            out.append(horizon_depths(depth, self.geo))
        return np.concatenate(out)


def _pool(dataset: Dataset, entries: list[RunEntry], geo: Geometry, config: Any, rng: np.random.Generator,
          progress: bool) -> tuple[np.ndarray, np.ndarray]:
    """Reduced frame triplets (F, 3, 3, rows, cols) float16 (t − 1, t, t + 1) and their
    `source_from_target` (F, 2, 4, 4) of up to `config.pool_frames` random frames t of each run whose
    camera moved from both neighbours."""
    triplets, transforms = [], []
    for entry in Bar(entries, desc="monodepth pool", unit="run", disable=not progress):
        run = dataset.read_run(entry, images=True)
        cameras = camera_poses(run.poses, geo)[:, :3, 3]
        step = np.linalg.norm(np.diff(cameras, axis=0), axis=1)
        moving = 1 + np.flatnonzero((step[:-1] >= MIN_MOVE) & (step[1:] >= MIN_MOVE))
        for t in rng.choice(moving, size=min(config.pool_frames, len(moving)), replace=False):
            triplets.append(reduce(run.images[t - 1 : t + 2], geo).astype(np.float16))
            transforms.append(source_from_target(run.poses, int(t), (t - 1, t + 1), geo))
    if not triplets:
        raise DataError(f"{dataset.root}: no frame whose camera moved from both neighbours to learn depth "
                        "from")
    return np.stack(triplets), np.stack(transforms)


def train(dataset: Dataset, geo: Geometry, config: Any, progress: bool, device: torch.device
          ) -> tuple[DepthNet, list[float], float]:
    """The depth net learnt on `dataset`'s frames and poses (a LabellerConfig): (net, losses, val loss)."""
    rng = np.random.default_rng(config.seed)
    pooled = first_runs(dataset, "train", config.pool_runs, config.pool == "every_look")
    train_pool = _pool(dataset, pooled, geo, config, rng, progress)
    val_pool = _pool(dataset, dataset.entries("val"), geo, replace(config, pool_frames=1), rng, False)
    camera, depth_range = intrinsics(geo).to(device), (config.min_depth, config.max_depth)
    net = DepthNet(config.width, disparity_of(START_DEPTH, *depth_range)).to(device)

    def batch_loss(pool: tuple[np.ndarray, np.ndarray], idx: np.ndarray) -> torch.Tensor:
        frames = torch.from_numpy(pool[0][idx].astype(np.float32)).to(device)
        return loss(net, frames, torch.from_numpy(pool[1][idx]).to(device), camera, depth_range,
                    config.smoothness, config.brightness)

    optimizer = torch.optim.Adam(net.parameters(), lr=config.lr)
    losses = []
    for _ in Bar(range(config.steps), desc="train monodepth", unit="step", disable=not progress):
        value = batch_loss(train_pool, rng.choice(len(train_pool[0]), size=config.batch_size))
        optimizer.zero_grad(set_to_none=True)
        value.backward()
        optimizer.step()
        losses.append(value.item())
    with torch.no_grad():
        n = len(val_pool[0])
        val = np.mean([batch_loss(val_pool, np.arange(i, min(i + BATCH, n))).item()
                       for i in range(0, n, BATCH)])
    return net.cpu().eval(), losses, float(val)


def identity(config: Any, geometry: dict[str, Any], bins: dict[str, Any]) -> dict[str, Any]:
    """What fixes a monodepth labeller's output besides its weights (a LabellerConfig,
    `floor.geometry_record`, the bins' config)."""
    return {"method": "monodepth", "scale": config.scale, "width": config.width,
            "min_depth": config.min_depth, "max_depth": config.max_depth, "memory_s": config.memory_s,
            "geometry": geometry, "bins": bins}
