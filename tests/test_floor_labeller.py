"""The floor labeller (issue #32): depth bins from the camera and odometry alone, learnt from the robot's
future footprint; its geometry against hand-computed rows, its training on real frames, its labels."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError, DataError
from depthq.labellers import floor
from depthq.labellers.labeller import (
    CONFIG,
    LabellerConfig,
    check_applicable,
    label_dataset,
    load_labeller,
    train_labeller,
)
from depthq.sim.mjcf import CameraConfig, RobotConfig
from depthq.sim.sensors import BinConfig

TOY_FLOOR = {"method": "floor", "steps": 30, "batch_size": 4, "lr": 3e-3, "pool_runs": 4, "pool_frames": 3,
             "width": 8}


def _geometry(scale: int = 1) -> floor.Geometry:
    return floor.Geometry(CameraConfig(), RobotConfig(), BinConfig(), scale)


def test_a_floor_point_projects_to_the_hand_computed_pixel() -> None:
    geo = _geometry()
    focal = 205 / np.tan(np.deg2rad(52))  # 410 columns over 104°: 160.16 px
    assert geo.focal == pytest.approx(focal)
    # 1 m straight ahead of the camera (which sits 3.2 cm behind the axle), 0.24 m below it.
    u, v = geo.project(np.array([[1.0 - 0.032, 0.0], [0.5 - 0.032, 0.5], [-0.2, 0.0]]))
    assert u[0] == pytest.approx(205) and v[0] == pytest.approx(154 + focal * 0.24)
    assert u[1] == pytest.approx(205 - focal) and v[1] == pytest.approx(154 + focal * 0.48)  # 45° left
    assert np.isnan(u[2]) and np.isnan(v[2])  # behind the camera


def test_foot_rows_give_the_ranges_and_bins_of_a_straight_wall() -> None:
    geo = _geometry(scale=2)
    rows, cols = geo.shape
    # A wall 1 m ahead of the camera, square to the view: its foot is on one row in every column.
    bearings = np.deg2rad(np.linspace(60, -60, 400))
    _, v = geo.project(np.stack([1.0 - 0.032 + 0 * bearings, np.tan(bearings)], axis=1))
    assert np.allclose(v, rows / 2 + geo.focal * 0.24)
    readings = geo.ranges(np.full((1, cols), v[0]))[0]
    expected = np.minimum(1.0 / np.cos(np.deg2rad(51 - np.arange(104))), 2.0)
    assert np.allclose(readings, expected, atol=1e-5)
    bins = geo.bins_of(readings[None])[0]
    assert bins.shape == (26,) and np.allclose(bins, expected.reshape(26, 4).mean(axis=1), atol=1e-5)
    assert np.all(geo.ranges(np.full((1, cols), rows / 2)) == 2.0)  # a foot on the horizon: far


def test_a_recordings_frames_are_resized_to_the_camera_if_their_aspect_ratio_fits() -> None:
    geo = _geometry(scale=2)
    simulated = np.random.default_rng(0).integers(0, 256, (1, 308, 410, 3), dtype=np.uint8)
    boxed = floor.reduce(simulated, geo)  # the camera's own size: 2 × 2 box means
    assert boxed.shape == (1, 3, 154, 205)
    assert np.isclose(boxed[0, 0, 0, 0], simulated[0, :2, :2, 0].mean() / 255)
    grey = np.full((2, 24, 32, 3), 128, np.uint8)  # a 32 × 24 robot camera: 4:3, as 410 × 308
    resized = floor.reduce(grey, geo)
    assert resized.shape == (2, 3, 154, 205) and np.allclose(resized, 128 / 255)
    with pytest.raises(DataError, match="50 × 30 pixels"):
        floor.reduce(np.zeros((1, 30, 50, 3), np.uint8), geo)


def test_the_memory_keeps_an_obstacle_that_earlier_frames_saw() -> None:
    geo = _geometry()
    ahead = 51  # the reading straight ahead (bearing 0)
    readings = np.full((4, 104), 2.0, np.float32)
    readings[0, ahead] = 1.0  # frame 0 sees a wall 1 m ahead; the later frames lose it
    # Straight ahead along x, 0.25 m per frame, 0.5 s apart: the wall comes 0.25 m nearer each frame.
    poses = np.array([[0.25 * t, 0.0, 0.0] for t in range(4)])
    times = np.array([0.0, 0.5, 1.0, 1.5])
    fused = floor.remember(readings, poses, times, geo, memory_s=1.0)
    assert np.allclose(fused[:3, ahead], [1.0, 0.75, 0.5], atol=1e-6)
    assert fused[3, ahead] == 2.0  # frame 0 is 1.5 s back: beyond the memory
    others = np.delete(np.arange(104), ahead)
    assert np.all(fused[:, others] == 2.0)  # nothing else seen, nothing made up
    assert np.array_equal(floor.remember(readings, poses, times, geo, memory_s=0.0), readings)
    # Turned 10° to the left on the spot (the sensor sits behind the axle, so it moves a little too).
    turned = floor.remember(readings[:2], np.array([[0, 0, 0], [0, 0, np.deg2rad(10)]]), times[:2], geo, 1.0)
    assert turned[1].argmin() == ahead + 10 and abs(turned[1].min() - 1.0) < 0.01


def test_foot_rows_find_the_first_blocked_pair_from_the_bottom() -> None:
    geo = _geometry(scale=2)
    rows, cols = geo.shape
    p = np.zeros((1, rows, cols), np.float32)
    p[0, 100:] = 1.0  # floor from row 100 down
    p[0, 120, 5] = 0.0  # one stray non-floor pixel does not end the floor
    feet = floor.foot_rows(p, geo, nearest=0.3)
    assert np.all(feet == 100)
    p[0, :] = 1.0  # floor up to the horizon and beyond: nothing in view
    assert np.all(floor.foot_rows(p, geo, nearest=0.3) == np.ceil(rows / 2))


def test_the_footprint_of_a_straight_drive_lies_ahead_below_the_horizon() -> None:
    geo = _geometry(scale=2)
    poses = np.array([[0.125 * t, 0.0, 0.0] for t in range(12)], dtype=np.float32)
    mask = floor.footprint(geo, poses, 0, frames=10, nearest=0.3)
    rows, cols = np.nonzero(mask)
    assert mask.any() and rows.min() > geo.shape[0] / 2  # floor only below the horizon
    assert abs(cols.mean() - geo.shape[1] / 2) < 1.5  # centred: straight ahead
    theta = 0.125 * np.arange(12)  # an arc of 1 m radius to the left
    arc = np.stack([np.sin(theta), 1 - np.cos(theta), theta], axis=1)
    turned = floor.footprint(geo, arc, 0, frames=10, nearest=0.3)
    assert turned.any() and np.nonzero(turned)[1].mean() < cols.mean() - 10  # off to the left


@pytest.mark.slow  # a toy floor labeller's training on real frames and a labelling: ~20 s
def test_the_floor_labeller_learns_from_real_frames_and_labels_its_own_family(
        small_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = train_labeller(LabellerConfig(data=str(small_dataset), **TOY_FLOOR), tmp_path / "floor",
                            progress=False, device="cpu")
    record = json.loads((folder / CONFIG).read_text())
    assert record["name"] == "floor" and record["source"]["family"] == "paper"
    assert record["losses"][-1] < record["losses"][0]  # the footprint loss falls
    assert np.isfinite(record["val_loss"])
    root = tmp_path / "data"
    shutil.copytree(small_dataset, root, ignore=shutil.ignore_patterns("features"))
    # Learnt from the camera and odometry of this very family: allowed, no depth went in.
    assert main(["label", str(root), "--from", "camera", "--labeller", str(folder), "--no-progress"]) == 0
    dataset, labeller = Dataset.open(root), load_labeller(folder)
    for entry in dataset.entries():
        with dataset.reader(entry) as reader:
            held = reader.camera_labels()
            run = reader.run(images=True)
            frames = run.images
        assert held is not None and held.labeller == "floor" and held.fingerprint == labeller.fingerprint
        assert held.bins.shape == (len(frames), 26)
        assert np.all((held.bins >= 0) & (held.bins <= 2.0))
        assert np.array_equal(held.bins, labeller.estimate(run))  # read back, bit for bit
    assert label_dataset(dataset, labeller, progress=False) == (0, len(dataset.entries()))  # resumed: none
    assert main(["dataset", "stats", str(root)]) == 0
    assert "camera labels (floor" in capsys.readouterr().out
    model = tmp_path / "model"
    assert main(["train", "--model", "depth", "--data", str(root), "--labels", "camera", "--epochs", "1",
                 "--train-batches", "2", "--val-batches", "1", "--batch-size", "8", "--out", str(model),
                 "--no-progress"]) == 0
    # The rows → ranges geometry is the camera's: another camera height would give wrong distances.
    camera = {**labeller.record["geometry"]["camera"], "mount_height": 0.3}
    other = replace(labeller, record={**labeller.record, "geometry": {**labeller.record["geometry"],
                                                                      "camera": camera}})
    with pytest.raises(ConfigError, match="floor rows"):
        check_applicable(other, dataset)


def test_a_labeller_method_must_be_one_it_knows() -> None:
    with pytest.raises(ConfigError, match="stereo"):
        LabellerConfig(data="data", method="stereo")
