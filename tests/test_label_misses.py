"""The floor labels' experiments: near-obstacle errors (`research.label_misses`), which
obstacle a bin's nearest reading hits by hand and the split on a toy floor labeller's labels of
hard-family runs, its counts checked against the run files; and the memory length
(`research.label_memory`), its rows against the labels `depthq label` writes."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.data.stats import label_errors
from depthq.labellers.labeller import LabellerConfig, train_labeller
from depthq.sim.sensors import BinConfig
from research import label_bands, label_memory, label_misses

TOY_FLOOR = {"method": "floor", "steps": 5, "batch_size": 4, "pool_runs": 2, "pool_frames": 3, "width": 8}


def test_a_bins_nearest_reading_hits_the_pillar_it_reads() -> None:
    bins = BinConfig()
    scan = np.full(360, np.inf, np.float32)
    scan[0] = 1.0  # straight ahead: bin 12's readings are bearings 3, 2, 1, 0
    scan[2] = 1.5
    pose = np.array([2.0, 1.0, np.pi / 2])  # facing +y; the sensor 3.2 cm behind the axle
    hits = label_misses.nearest_hits(scan, pose, bins, offset_x=-0.032)
    assert np.allclose(hits[12], [2.0, 1.0 - 0.032 + 1.0])
    assert np.isnan(hits[np.arange(26) != 12]).all()  # no valid reading: no hit
    pillar = np.array([[2.0, 2.2, 0.25]])  # centre 0.232 m beyond the hit, radius 0.25: the hit is on it
    moved = pillar + np.array([1.0, 0.0, 0.0])  # 1 m to the side
    assert label_misses.is_pillar(hits[12], pillar) and not label_misses.is_pillar(hits[12], moved)
    assert not label_misses.is_pillar(hits[12], np.zeros((0, 3)))  # the paper's canyons have none


def test_a_band_mix_takes_the_lidar_where_it_reads_in_the_band() -> None:
    lidar = np.array([[0.4, 1.0, 1.7, np.nan]], np.float32)
    camera = np.array([[0.9, 0.8, 2.0, 0.5]], np.float32)
    near, far = (label_bands.mixed(lidar, camera, band, 1.0) for band in ("near", "far"))
    assert np.array_equal(near, np.float32([[0.4, 0.8, 2.0, 0.5]]))  # the LiDAR under 1 m
    assert np.array_equal(far, np.float32([[0.9, 1.0, 1.7, 0.5]]))  # from 1 m on; invalid: the camera


@pytest.mark.slow  # a toy floor labeller and a labelling of the hard family's small dataset: ~15 s
def test_the_experiment_splits_every_near_bin_by_what_it_hits(
        small_hard_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "data"
    shutil.copytree(small_hard_dataset, root, ignore=shutil.ignore_patterns("features"))
    labeller = train_labeller(LabellerConfig(data=str(root), **TOY_FLOOR), tmp_path / "floor", progress=False,
                              device="cpu")
    assert main(["label", str(root), "--from", "camera", "--labeller", str(labeller), "--no-progress"]) == 0
    dataset = Dataset.open(root)
    result = label_misses.measure(dataset, "train", near=2.0)
    near = 0
    for entry in dataset.entries("train"):
        run = dataset.read_run(entry, images=False)
        near += int((np.isfinite(run.bins) & np.isfinite(run.camera.bins) & (run.bins < 2.0)).sum())
    kinds = result["kinds"]
    assert kinds["pillar"]["bins"] + kinds["wall"]["bins"] == near > 0
    for kind in kinds.values():
        if kind["bins"]:
            assert kind["under"] + kind["within"] + kind["missed"] == pytest.approx(1.0, abs=1e-3)
    out = tmp_path / "misses.json"
    assert label_misses.main([str(root), "--split", "train", "--near", "2", "--json", str(out)]) == 0
    assert "| wall |" in capsys.readouterr().out and out.is_file()
    assert label_misses.main([str(root), "--near", "0.5", "--far", "0.5"]) == 2  # an empty band
    assert "--far and --near" in capsys.readouterr().err


    # The memory lengths: the labeller's own (2 s, its default) gives what `depthq label` wrote.
    memory = label_memory.measure(labeller, dataset, (0.0, 2.0), split="train", progress=False)
    written = [dataset.read_run(e, images=False) for e in dataset.entries("train")]
    truth = np.concatenate([r.bins for r in written])
    labels = np.concatenate([r.camera.bins for r in written])
    assert memory["memory_s"]["2.0"] == label_errors(truth, labels, len(written))
    assert memory["memory_s"]["0.0"]["frames"] == memory["memory_s"]["2.0"]["frames"]
    assert label_memory.main([str(labeller), str(root), "--memory", "0,x"]) == 2
    assert "--memory must be seconds" in capsys.readouterr().err
