"""A trunk tuned from cached activations (docs/design.md#tuned-trunk): EfficientNet-Lite0 split after a
stage, its early stages' map cached per frame, its late stages trained with the head. Real frames, real
ImageNet weights, real files; no mocks."""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from depthq.blocks.trunk import (
    DEFAULT_TRUNK,
    STAGES,
    build_early_trunk,
    build_trunk,
    early_map_shape,
    early_trunk_name,
    preprocess,
)
from depthq.checkpoint import load_qnet
from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target
from depthq.data.views import view_arrays
from depthq.errors import ConfigError, DataError
from depthq.networks import DepthSettings
from depthq.policies.qnet import QNetPolicy
from depthq.train.config import TrainConfig
from depthq.train.features import ARRAY, INDEX, cache_dir, load_activations, verify_caches
from depthq.train.samples import ActivationSamples
from depthq.train.trainer import train

FAST = {"epochs": 2, "train_batches": 3, "val_batches": 1, "batch_size": 8, "hidden": 32}


def _frames(dataset: Dataset, split: str = "train", runs: int = 2) -> np.ndarray:
    frames = []
    for entry in dataset.entries(split)[:runs]:
        with dataset.reader(entry) as reader:
            frames += [reader.image(t) for t in range(0, entry.n_frames, 5)]
    return np.stack(frames)


@pytest.mark.slow
def test_early_then_late_stages_are_the_whole_trunk_on_real_frames(small_dataset: Path) -> None:
    images = preprocess(_frames(Dataset.open(small_dataset)))
    with torch.inference_mode():
        whole = build_trunk(DEFAULT_TRUNK)(images)
        for tune in (1, 2, 3, STAGES):
            early, tuned = build_early_trunk(STAGES - tune, 128), build_trunk(DEFAULT_TRUNK, tune_stages=tune)
            channels, side, _ = early_map_shape(STAGES - tune, 128)
            activations = early(images)
            assert activations.shape == (len(images), channels * side * side)
            torch.testing.assert_close(tuned.late_features(activations), whole, atol=1e-4, rtol=1e-4)
            torch.testing.assert_close(tuned(images), whole, atol=1e-4, rtol=1e-4)  # a policy's path
            stored = tuned.late_features(activations.half().float())  # as the float16 cache holds them
            torch.testing.assert_close(stored, whole, atol=6e-2, rtol=2e-2)
            assert (stored - whole).abs().mean() < 0.01 * whole.abs().mean()
    assert early_map_shape(5, 128) == (112, 8, 8) and early_map_shape(6, 128) == (192, 4, 4)


@pytest.mark.slow
def test_mirrored_activations_are_those_of_the_flipped_frames_not_the_flipped_map(
    small_dataset: Path,
) -> None:
    """TensorFlow's "SAME" padding of a stride-2 conv pads the right only, so the early stages do not
    commute with a flip: the mirrored cache is computed from flipped frames."""
    dataset = Dataset.open(small_dataset)
    table = load_activations(dataset, 2, 128, progress=False)
    mirrored = load_activations(dataset, 2, 128, progress=False, mirrored=True)
    entry = dataset.entries("train")[0]
    with dataset.reader(entry) as reader:
        frame = reader.image(3)
    early = build_early_trunk(STAGES - 2, 128)
    with torch.inference_mode():
        plain, flipped = early(preprocess(frame)), early(preprocess(frame).flip(-1))
    row = mirrored.runs[entry.name][0] + 3
    close = {"atol": 2e-2, "rtol": 1e-2}  # float16
    np.testing.assert_allclose(mirrored.features[row].astype(np.float32), flipped[0].numpy(), **close)
    np.testing.assert_allclose(table.features[row].astype(np.float32), plain[0].numpy(), **close)
    flipped_map = plain.reshape(1, 112, 8, 8).flip(-1).flatten(1)
    assert (flipped_map - flipped).abs().mean() > 0.2 * flipped.abs().mean()  # far from equivariant

    arrays = view_arrays(dataset, "train", None, bins_target)
    samples = ActivationSamples(arrays, table, "train", mirrored=mirrored)
    idx = samples.draw(200, np.random.default_rng(0))
    batch, m = samples.batch(idx), idx[:, 1].bool()
    rows = table.rows("train", arrays["run_id"], arrays["frame_id"])[idx[:, 0].numpy()]
    expected = np.where(m.numpy()[:, None], mirrored.features[rows], table.features[rows]).astype(np.float32)
    np.testing.assert_array_equal(batch.inputs.numpy(), expected)
    torch.testing.assert_close(batch.actions[m], -torch.from_numpy(arrays["action"][idx[m, 0].numpy()]))


@pytest.mark.slow
def test_a_tuned_training_stores_its_late_stages_reloads_resumes_and_acts_as_trained(
    small_dataset: Path, tmp_path: Path
) -> None:
    dataset = Dataset.open(small_dataset)
    config = TrainConfig(model="depth", data=str(small_dataset), tune_stages=1, mirror=True, **FAST)
    out = train(config, tmp_path / "tuned", progress=False)
    record = json.loads((out / "config.json").read_text())
    assert record["train"]["tune_stages"] == 1 and record["trunk_frozen"] is False
    saved = load_file(out / "last.safetensors")
    trunk_keys = {k for k in saved if k.startswith("trunk.")}
    tuned = build_trunk(DEFAULT_TRUNK, tune_stages=1)
    assert trunk_keys == {f"trunk.{k}" for k in tuned.net.late.state_dict()}  # the late stages only
    start = tuned.net.late.state_dict()
    assert any(not torch.equal(saved[f"trunk.{k}"], v) for k, v in start.items()), "the stages did not move"

    net, _ = load_qnet(out, "last")
    entry = dataset.entries("val")[0]
    with dataset.reader(entry) as reader:
        frame = reader.image(2)
    table = load_activations(dataset, 1, 128, progress=False)
    cached = torch.from_numpy(table.features[table.runs[entry.name][0] + 2][None].astype(np.float32))
    actions = torch.tensor([-1.0, 0.0, 1.0])
    with torch.inference_mode():
        # the values as training computes them: the late stages on the cached activations
        trained_values = net.candidate_outputs(net.trunk.late_features(cached), actions)[0]
    policy = QNetPolicy.from_checkpoint(out, weights="last")
    np.testing.assert_allclose(policy.values(frame), trained_values.numpy(), atol=2e-2, rtol=1e-2)

    from depthq.train.offline_metric import offline_metric  # on the cached activations

    metric = offline_metric(out, dataset, weights="last")
    assert metric["samples"] > 0 and np.isfinite(metric["value"])
    from research.weights_check import measure  # its dead outputs, with each choice's stages

    checked = measure(out, ("final", "average"), frames=12)
    assert checked["final"]["frames"] == 12 and isinstance(checked["average"]["dead_bins"], list)

    # resumed after its first epoch, it writes the weights an uninterrupted training writes
    once = train(replace(config, epochs=1), tmp_path / "resumed", progress=False)
    train(config, once, progress=False)
    for name in ("last.safetensors", "average.safetensors"):
        assert (once / name).read_bytes() == (out / name).read_bytes(), name

    pytest.importorskip("onnxruntime")
    from depthq.deploy.onnx_export import export_onnx
    from depthq.policies.onnx import OnnxPolicy

    onnx = OnnxPolicy(export_onnx(out, tmp_path / "onnx"))
    np.testing.assert_allclose(onnx.values(frame), QNetPolicy.from_checkpoint(out).values(frame), atol=1e-4)


@pytest.mark.slow
def test_the_activation_cache_is_reused_recomputed_when_incomplete_and_checked(
    small_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = shutil.copytree(small_dataset, tmp_path / "data", ignore=shutil.ignore_patterns("features"))
    dataset = Dataset.open(root)
    first = load_activations(dataset, 2, 64, progress=False)
    folder = cache_dir(root, early_trunk_name(STAGES - 2), 64)
    assert first.computed and (folder / INDEX).is_file()
    frames = sum(e.n_frames for e in dataset.entries())
    assert first.features.shape == (frames, 112 * 4 * 4) and first.features.dtype == np.float16
    stamp = (folder / INDEX).stat().st_mtime_ns
    assert not load_activations(dataset, 2, 64, progress=False).computed
    assert (folder / INDEX).stat().st_mtime_ns == stamp
    (folder / INDEX).unlink()  # an interrupted computation leaves no index: computed again
    again = load_activations(dataset, 2, 64, progress=False)
    assert again.computed
    np.testing.assert_array_equal(again.features, first.features)
    del first, again
    with (folder / ARRAY).open("r+b") as f:  # one byte of the last row: a value changes
        f.seek(-1, os.SEEK_END)
        byte = f.read(1)
        f.seek(-1, os.SEEK_END)
        f.write(bytes([byte[0] ^ 0x7C]))
    with pytest.raises(DataError, match="corrupted feature cache"):
        load_activations(dataset, 2, 64, progress=False)
    assert any(str(folder) in problem for problem in verify_caches(dataset))
    assert main(["dataset", "verify", str(root)]) == 1
    assert "corrupted feature cache" in capsys.readouterr().err


def test_bad_tune_stages_are_refused_by_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = {"model": "depth", "data": "d"}
    for bad in (-1, STAGES + 1, 1.5, True):
        with pytest.raises(ConfigError, match=f"tune_stages must be an integer in 0..{STAGES}"):
            TrainConfig(**base, tune_stages=bad)
    with pytest.raises(ConfigError, match="cannot be tuned from cached activations; tunable trunks"):
        TrainConfig(**base, trunk="mobilenet_v1_025", tune_stages=1)
    with pytest.raises(ConfigError, match="feature_projection 64"):
        TrainConfig(**base, tune_stages=1, feature_projection=64)
    with pytest.raises(ConfigError, match="bootstrap"):
        TrainConfig(**base, tune_stages=1, settings=DepthSettings(bootstrap=0.5))
    assert TrainConfig(**base, trunk="efficientnet_lite0_grid", tune_stages=STAGES).tune_stages == STAGES
    out = tmp_path / "out"
    args = ["train", "--model", "depth", "--data", str(tmp_path), "--tune-stages", "9", "--out", str(out)]
    assert main(args) == 2
    assert "tune_stages must be an integer in 0..7 (0: none), got 9" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_bench_train_times_a_tuned_trunk_beside_the_head(capsys: pytest.CaptureFixture[str]) -> None:
    from depthq.bench.train import bench_train

    r = bench_train(seconds=1.0, threads=1, tunes=(0, 1))
    head, tuned = r["variants"]["depth_first/fp32/tune0"], r["variants"]["depth_first/fp32/tune1"]
    assert head["tune_stages"] == 0 and tuned["tune_stages"] == 1
    assert 0 < tuned["samples_per_s"] < head["samples_per_s"]  # the stage's convolutions cost more
    for bad in ("0,x", "9"):
        assert main(["bench", "train", "--seconds", "1", "--tune-stages", bad]) == 2
        assert bad.split(",")[-1] in capsys.readouterr().err
