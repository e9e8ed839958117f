"""The monodepth labeller: a depth net learnt by warping each frame's neighbours into it with odometry's
poses (Monodepth2's self-supervision); its warp against a rendered pair's true depth, its training on
real frames, its labels.

Its training runs on the hard family's frames: each side's walls, the floor and the pillars have
colours of their own there, each wall piece a little different, so edges move between frames. The
paper family's walls are all one grey: a photometric loss sees little to warp there (the walls'
shading and their foot on the floor).
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import replace
from pathlib import Path

import kornia
import mujoco
import numpy as np
import pytest
import torch

from depthq.checksum import write_checked_json
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError
from depthq.labellers import floor, monodepth
from depthq.labellers.labeller import CONFIG, LabellerConfig, label_dataset, load_labeller, train_labeller
from depthq.sim.canyon import CanyonId, generate_canyon
from depthq.sim.mjcf import GROUND_GROUP, WALL_GROUP
from depthq.sim.world import CanyonWorld, WorldConfig, world_for

# scale 8 (51 × 38 pixels) and a batch of 12 drawn from 3 triplets: the loss falls clearly within 40
# steps, where batches of other triplets would hide it.
TOY_MONODEPTH = {"method": "monodepth", "scale": 8, "width": 8, "steps": 40, "batch_size": 12, "lr": 3e-3,
                 "pool_runs": 3, "pool_frames": 1}


def _true_depth(world: CanyonWorld, geo: floor.Geometry) -> np.ndarray:
    """The camera's depth (rows, cols) at `geo`'s pixel centres, ray cast by MuJoCo from the camera's own
    frame (its x right, y up, looking along −z): what the warp's camera axes must agree with."""
    model, data = world.model, world.data
    eye = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "eye")
    axes = data.cam_xmat[eye].reshape(3, 3)
    rows, cols = geo.shape
    v, u = np.mgrid[0:rows, 0:cols].astype(np.float64)
    right, down = (u - (cols - 1) / 2) / geo.focal, (v - (rows - 1) / 2) / geo.focal
    rays = right[..., None] * axes[:, 0] - down[..., None] * axes[:, 1] - axes[:, 2]
    length = np.linalg.norm(rays, axis=-1)
    groups = np.zeros(6, np.uint8)
    groups[[WALL_GROUP, GROUND_GROUP]] = 1
    distance, hit = np.zeros(rows * cols), np.zeros(rows * cols, np.int32)
    mujoco.mj_multiRay(model, data, data.cam_xpos[eye], (rays / length[..., None]).ravel(), groups, 1, -1,
                       hit, distance, None, rows * cols, 50.0)
    return (np.where(distance < 0, 50.0, distance).reshape(rows, cols) / length).astype(np.float32)


def test_the_odometry_warp_with_the_true_depth_matches_a_rendered_pair() -> None:
    config = world_for(WorldConfig(), "hard")
    world = CanyonWorld(config)
    try:
        canyon = CanyonId("val", 1000, "hard")
        world.load(generate_canyon(canyon, config.canyon), np.random.default_rng(canyon.appearance_seed))
        geo = floor.Geometry(config.camera, config.robot, floor.geometry(None, 2).bins, scale=2)
        # The target frame, and the source 0.15 m behind it, turned 7° to the right of it.
        poses = np.array([[0.02, 0.85, math.pi / 2 - 0.12], [0.0, 1.0, math.pi / 2]])
        frames = []
        for pose in poses:
            world.place(*pose)
            frames.append(world.render().copy())
        depth = torch.from_numpy(_true_depth(world, geo))[None, None]  # the target's, placed last
    finally:
        world.close()
    source, target = torch.from_numpy(floor.reduce(np.stack(frames), geo)).split(1)
    camera = monodepth.intrinsics(geo)[None]

    def error(poses: np.ndarray) -> float:
        transform = torch.from_numpy(monodepth.source_from_target(poses, 1, (0,), geo))
        warped = kornia.geometry.depth.warp_frame_depth(source, depth, transform, camera)
        seen = warped.sum(dim=1) > 0  # out of the source's view: zeros
        return (warped - target).abs().mean(dim=1)[seen].mean().item()

    unwarped = (source - target).abs().mean().item()
    mirrored = poses * [1, 1, -1] + [0, 0, math.pi]  # the turn the other way: a wrong yaw sign
    assert error(poses) < 0.3 * unwarped and error(poses) < 0.3 * error(mirrored)
    # The conventions spelled out (x right, y down, z forward): driving 0.1 m forward, a point 1 m ahead
    # of the target's camera is 0.9 m ahead of the source's; turned 90° left on the spot, the source's
    # camera (3.2 cm behind the axle) sits 3.2 cm right of and ahead of the target's, looking left.
    def moved(pose: list[float]) -> np.ndarray:
        return monodepth.source_from_target(np.array([[0.0, 0, 0], pose]), 0, (1,), geo)[0]

    assert np.allclose(moved([0.1, 0, 0]) @ [0, 0, 1, 1], [0, 0, 0.9, 1], atol=1e-6)
    turned = np.linalg.inv(moved([0, 0, math.pi / 2]))  # source → target
    assert np.allclose(turned[:3, 3], [0.032, 0, 0.032], atol=1e-6)
    assert np.allclose(turned[:3, 2], [-1, 0, 0], atol=1e-6)


def test_the_horizon_rows_give_the_readings_of_a_wall() -> None:
    geo = floor.Geometry(WorldConfig().camera, WorldConfig().robot, floor.geometry(None, 2).bins, scale=4)
    depth = np.full((1, *geo.shape), 10.0, np.float32)
    depth[0, geo.shape[0] // 2 - 2 : geo.shape[0] // 2 + 3] = 1.0  # a wall 1 m ahead, square to the view
    depth[0, geo.shape[0] // 2, :10] = 0.2  # one stray row does not move the median
    readings = monodepth.horizon_depths(depth, geo)[0]
    expected = np.minimum(1.0 / np.cos(np.deg2rad(51 - np.arange(104))), 2.0)
    assert np.allclose(readings, expected, atol=1e-5)


@pytest.mark.slow  # a toy monodepth labeller's training on real frames and a labelling: ~15 s
def test_the_monodepth_labeller_learns_from_real_frames_and_labels_them(small_hard_dataset: Path,
                                                                         tmp_path: Path) -> None:
    folder = train_labeller(LabellerConfig(data=str(small_hard_dataset), **TOY_MONODEPTH), tmp_path / "mono",
                            progress=False, device="cpu")
    record = json.loads((folder / CONFIG).read_text())
    assert record["name"] == "monodepth" and record["geometry"]["camera"]["mount_height"] == 0.24
    assert record["losses"][-1] < 0.8 * record["losses"][0]  # the photometric loss falls
    assert np.isfinite(record["val_loss"])
    root = tmp_path / "data"
    shutil.copytree(small_hard_dataset, root, ignore=shutil.ignore_patterns("features"))
    dataset, labeller = Dataset.open(root), load_labeller(folder)
    assert labeller.fingerprint == record["fingerprint"]
    # Learnt from the camera and odometry of this very dataset: allowed, no depth went in.
    assert label_dataset(dataset, labeller, progress=False) == (len(dataset.entries()), 0)
    for entry in dataset.entries():
        with dataset.reader(entry) as reader:
            held = reader.camera_labels()
        assert held is not None and held.labeller == "monodepth" and held.fingerprint == labeller.fingerprint
        assert held.bins.shape == (entry.n_frames, 26) and np.isfinite(held.bins).all()
        assert np.all((held.bins >= 0) & (held.bins <= 2.0))


@pytest.mark.parametrize("brightness", ["gain", "affine"])
def test_brightness_compensation_recovers_a_known_exposure_and_white_balance(brightness: str) -> None:
    rng = np.random.default_rng(0)
    target = torch.from_numpy(rng.uniform(0.1, 0.9, (2, 3, 20, 24)).astype(np.float32))
    gain = torch.tensor([[0.5, 0.8, 1.6], [1.3, 1.0, 0.7]])[..., None, None]
    bias = torch.tensor([[0.1, -0.05, 0.02], [0.0, 0.15, -0.1]])[..., None, None]
    if brightness == "gain":
        bias = torch.zeros_like(bias)
    source = (target - bias) / gain  # what a camera of another exposure and white balance gave
    valid = torch.ones_like(target[:, :1], dtype=torch.bool)
    valid[:, :, :, :6] = False  # out of the source's view: other content, ignored by the fit
    source[:, :, :, :6] = torch.from_numpy(rng.uniform(0, 1, (2, 3, 20, 6)).astype(np.float32))
    fixed = monodepth.compensate(source, target, valid, brightness)
    assert torch.allclose(fixed[:, :, :, 6:], target[:, :, :, 6:], atol=1e-5)
    assert not torch.allclose(source[:, :, :, 6:], target[:, :, :, 6:], atol=0.05)
    assert monodepth.compensate(source, target, valid, "none") is source


def test_brightness_compensation_takes_out_an_exposure_change_from_the_loss() -> None:
    """A triplet whose neighbours are the target itself, taken at other exposures: with the true (no)
    motion the compensated loss is nil, the uncompensated one is not."""
    geo = floor.Geometry(WorldConfig().camera, WorldConfig().robot, floor.geometry(None, 2).bins, scale=8)
    rng = np.random.default_rng(1)
    target = torch.from_numpy(rng.uniform(0.2, 0.8, (1, 3, *geo.shape)).astype(np.float32))
    frames = torch.stack([target * 0.6, target, target * 1.2 + 0.05], dim=1)
    transforms = torch.eye(4).expand(1, 2, 4, 4)
    camera = monodepth.intrinsics(geo)[None]
    net = monodepth.DepthNet(4)

    def loss(brightness: str) -> float:
        return monodepth.loss(net, frames, transforms, camera, (0.1, 10.0), 0.0, brightness).item()

    assert loss("affine") < 1e-3 < 0.02 < loss("none")


@pytest.mark.slow  # a few toy steps with brightness compensation on real frames: ~5 s
def test_a_labeller_learns_with_brightness_compensation_and_records_it(small_hard_dataset: Path,
                                                                       tmp_path: Path) -> None:
    config = LabellerConfig(data=str(small_hard_dataset), **{**TOY_MONODEPTH, "steps": 4},
                            brightness="affine")
    folder = train_labeller(config, tmp_path / "mono", progress=False, device="cpu")
    record = json.loads((folder / CONFIG).read_text())
    assert record["config"]["brightness"] == "affine" and np.isfinite(record["losses"]).all()
    assert load_labeller(folder).record["config"]["brightness"] == "affine"
    assert train_labeller(config, folder, progress=False) == folder  # the same labeller: kept
    with pytest.raises(ConfigError, match="holds another labeller"):
        train_labeller(replace(config, brightness="gain"), folder, progress=False)
    # A folder written before the setting learnt without compensation, and loads as such.
    del record["config"]["brightness"], record["sha256"]
    write_checked_json(folder / CONFIG, record)
    assert load_labeller(folder).record["config"].get("brightness") is None
    assert train_labeller(replace(config, brightness="none"), folder, progress=False) == folder


@pytest.mark.parametrize(("setting", "value"), [("min_depth", -0.1), ("max_depth", 0.05), ("smoothness", -1),
                                                ("brightness", "auto")])
def test_a_bad_monodepth_setting_is_refused_by_name(setting: str, value: float) -> None:
    with pytest.raises(ConfigError, match=f"labeller.{setting} must be"):
        LabellerConfig(data="data", method="monodepth", **{setting: value})
