"""Mirrored training samples (docs/design.md#mirror): the features of the flipped frames, the action
negated, the bins reversed; real frames and trunk on conftest's small dataset, no mocks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from depthq.blocks.trunk import DEFAULT_TRUNK, build_trunk, preprocess
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target
from depthq.data.views import view_arrays
from depthq.errors import ConfigError
from depthq.train.config import TrainConfig
from depthq.train.features import load_features
from depthq.train.samples import FeatureSamples
from depthq.train.trainer import train


@pytest.mark.slow
def test_mirrored_samples_are_the_flipped_frames_with_the_turn_and_bins_reversed(small_dataset: Path) -> None:
    dataset = Dataset.open(small_dataset)
    table = load_features(dataset, DEFAULT_TRUNK, 128, progress=False)
    mirrored = load_features(dataset, DEFAULT_TRUNK, 128, progress=False, mirrored=True)
    entry = dataset.entries("train")[0]
    with dataset.reader(entry) as reader:
        frame = reader.image(3)
    with torch.inference_mode():
        flipped = build_trunk(DEFAULT_TRUNK)(preprocess(frame[None]).flip(-1))[0].numpy()
    row = mirrored.runs[entry.name][0] + 3
    np.testing.assert_allclose(mirrored.features[row].astype(np.float32), flipped, rtol=2e-3, atol=2e-3)
    assert not np.array_equal(mirrored.features[row], table.features[row])

    arrays = view_arrays(dataset, "train", None, bins_target)
    samples = FeatureSamples(arrays, table, "train", mirrored=mirrored)
    rng = np.random.default_rng(0)
    idx = samples.draw(400, rng)
    assert 0.4 < idx[:, 1].float().mean() < 0.6  # about half taken mirrored
    batch = samples.batch(idx)
    i, m = idx[:, 0], idx[:, 1].bool()
    plain = FeatureSamples(arrays, table, "train").batch(torch.stack([i, torch.zeros_like(i)], dim=1))
    torch.testing.assert_close(batch.actions, torch.where(m, -plain.actions, plain.actions))
    torch.testing.assert_close(batch.targets[m], plain.targets[m].flip(-1), equal_nan=True)
    torch.testing.assert_close(batch.targets[~m], plain.targets[~m], equal_nan=True)
    torch.testing.assert_close(batch.inputs[~m], plain.inputs[~m])
    assert not torch.equal(batch.inputs[m], plain.inputs[m])


@pytest.mark.slow
def test_a_mirrored_training_records_it_and_needs_a_frozen_trunk(small_dataset: Path, tmp_path: Path) -> None:
    fast = {"model": "coll", "data": str(small_dataset), "epochs": 1, "train_batches": 3, "val_batches": 1,
            "batch_size": 8, "hidden": 32}
    folder = train(TrainConfig(**fast, mirror=True), tmp_path / "mirror", progress=False)
    assert json.loads((folder / "config.json").read_text())["train"]["mirror"] is True
    with pytest.raises(ConfigError, match="mirror"):
        TrainConfig(**{**fast, "trunk": "mobilenet_v1_025"}, mirror=True)
