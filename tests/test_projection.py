"""The optional feature projection (`TrainConfig.feature_projection`, docs/design.md#heads): P = 0 is
the head without it to the bit; P > 0 is numpy's PCA of the training features, fitted once, carried
by checkpoints, policies (lock-step bits included) and the ONNX graph. Real trainings, no mocks."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import unchecked
from paper_head import paper_head
from safetensors.torch import load_file
from test_lockstep import assert_batch_decides_as_alone
from test_lookahead import _one_step_head_by_hand

from depthq.blocks.heads import QNet, pca_projection
from depthq.blocks.optim import make_optimizer
from depthq.checkpoint import load_qnet
from depthq.cli import main
from depthq.configio import from_dict
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError
from depthq.flags import config_from_args
from depthq.networks import build_head, get_network
from depthq.policies.qnet import BATCH_FRAMES, QNetPolicy
from depthq.train.config import TrainConfig
from depthq.train.features import load_features
from depthq.train.trainer import train

FAST = {"epochs": 2, "train_batches": 4, "val_batches": 1, "batch_size": 16}


def test_projection_zero_is_the_head_without_it_to_the_bit() -> None:
    hidden, output = _one_step_head_by_hand(256, seed=7)  # the paper's head, before any option
    torch.manual_seed(7)
    head = build_head(paper_head("depth", 256, dropout=0.0, action_scale=10.0, feature_projection=0)).eval()
    assert head.projection is None
    assert list(head.state_dict()) == ["hidden.weight", "hidden.bias", "output.weight", "output.bias"]
    for name, layer in (("hidden", hidden), ("output", output)):
        assert torch.equal(head.state_dict()[f"{name}.weight"], layer.weight)
    feature, action = torch.randn(5, 256), torch.tensor([-1.0, 0.0, 1.0, 0.5, -0.2])
    by_hand = torch.relu(output(torch.relu(hidden(torch.cat([feature, 10.0 * action[:, None]], dim=1)))))
    with torch.no_grad():
        assert torch.equal(head(feature, action), by_hand)

    for kind, k in (("depth", 3), ("coll", 1)):  # and every other head: no projection, no buffers
        zero = build_head(paper_head(kind, 64, hidden=32, lookahead=k, feature_projection=0))
        assert zero.projection is None and not any("projection" in key for key in zero.state_dict())
    # A record written before the field reads as 0: tests/test_checkpoint.py (the head's added fields).


def test_the_projection_is_numpys_pca_fixed_in_sign_and_deterministic() -> None:
    rng = np.random.default_rng(0)
    basis, _ = np.linalg.qr(rng.normal(size=(48, 48)))
    scales = np.geomspace(10.0, 0.1, 48)  # distinct variances: each direction is well defined
    features = (rng.normal(size=(9000, 48)) * scales @ basis.T + 3.0).astype(np.float16)  # 2 blocks
    weight, bias = pca_projection(features, 6)
    assert weight.shape == (6, 48) and bias.shape == (6,) and weight.dtype == bias.dtype == torch.float32

    x = features.astype(np.float64)
    _, _, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    top = vt[:6] * np.sign(vt[np.arange(6), np.abs(vt[:6]).argmax(axis=1)])[:, None]
    np.testing.assert_allclose(weight.numpy(), top, atol=1e-5)
    np.testing.assert_allclose(bias.numpy(), -top @ x.mean(axis=0), rtol=1e-5, atol=1e-5)
    assert all(row[np.abs(row).argmax()] > 0 for row in weight.numpy())  # the sign convention
    again = pca_projection(features.copy(), 6)
    assert torch.equal(again[0], weight) and torch.equal(again[1], bias)

    torch.manual_seed(0)
    head = build_head(paper_head("coll", 48, hidden=32, action_scale=10.0, feature_projection=6))
    head.fit_projection(features)
    assert {n for n, _ in head.named_buffers()} == {"projection.weight", "projection.bias"}
    assert torch.equal(head.projection.weight, weight) and head.hidden.in_features == 7
    optimizer = make_optimizer(head, 0.1)  # buffers, not parameters: the optimizer never sees them
    assert sum(len(g["params"]) for g in optimizer.param_groups) == len(list(head.parameters())) == 6
    f, a = torch.from_numpy(features[:8].astype(np.float32)), torch.linspace(-1, 1, 8)
    by_hand = head.output(torch.relu(head.hidden(torch.cat([f @ weight.T + bias, 10.0 * a[:, None]], 1))))
    with torch.no_grad():
        torch.testing.assert_close(head.eval()(f, a), by_hand.squeeze(1), rtol=0, atol=1e-5)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"feature_projection": -1}, "train.feature_projection must be an integer >= 0, got -1"),
        ({"feature_projection": 2.5}, "train.feature_projection must be an integer >= 0, got 2.5"),
        ({"feature_projection": 1281}, r"train.feature_projection must be in 1..1280 .* got 1281"),
        ({"trunk": "mobilenet_v1_025", "feature_projection": 8},
         "train.feature_projection 8: only a frozen trunk's cached features are projected"),
        ({"trunk": "efficientnet_lite0_columns_tuned", "feature_projection": 256},
         "train.feature_projection 256: only a frozen"),
    ],
)
def test_bad_projections_are_refused_by_value(changes: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        TrainConfig(**{"model": "depth", "data": "data", **changes})


def test_flags_sweep_and_head_take_the_projection(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import parse_setting
    from depthq.scripts.train import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--model", "coll", "--data", "d", "--out", "o", "--feature-projection", "256"])
    assert config_from_args(TrainConfig, args).feature_projection == 256
    assert main(["train", "--model", "depth", "--data", str(tmp_path), "--out", str(tmp_path / "o"),
                 "--feature-projection", "2000"]) == 2
    assert "feature_projection" in capsys.readouterr().err and not (tmp_path / "o").exists()

    assert parse_setting("feature_projection=0,256") == ("feature_projection", (0, 256))
    sweep = replace(get_preset("smoke"), grid=(parse_setting("feature_projection=0,256"),))
    names = {m.name for m in sweep.models()}
    assert {"depth_n3_s0", "coll_n3_s0", "depth_n3_s0_feature_projection256",
            "coll_n6_s0_feature_projection256"} <= names  # both networks: each is projected
    assert {sweep.train_config(m, "d").feature_projection for m in sweep.models()} == {0, 256}

    with pytest.raises(ConfigError, match=r"projection must be an integer in 0..64 \(0: none\), got 65"):
        paper_head("depth", 64, feature_projection=65)
    with pytest.raises(ConfigError, match="this head has no feature projection"):
        build_head(paper_head("depth", 64)).fit_projection(np.zeros((4, 64), np.float16))


@pytest.fixture(scope="module")
def projected(tmp_path_factory: pytest.TempPathFactory, small_dataset: Path) -> Path:
    """A Depth-Q-Net whose 1280-d feature is projected to 8 numbers, trained on conftest's small dataset
    for one epoch, then resumed for a second (which loads the projection from the checkpoint)."""
    config = TrainConfig(model="depth", data=str(small_dataset), feature_projection=8, **FAST)
    out = tmp_path_factory.mktemp("projection") / "p8"
    train(replace(config, epochs=1), out, progress=False)
    return train(config, out, progress=False)


def _config_of(folder: Path) -> TrainConfig:
    return from_dict(TrainConfig, json.loads((folder / "config.json").read_text())["train"])


def _training_features(config: TrainConfig) -> np.ndarray:
    """The cached features of `config`'s training samples, as the trainer gathers them."""
    dataset = Dataset.open(Path(config.data))
    arrays = get_network(config.model).samples(dataset, "train", config.runs, config)
    table = load_features(dataset, config.trunk, config.input_size, progress=False)
    return table.gather("train", arrays).numpy()


@pytest.mark.slow
def test_a_projected_training_fits_once_and_resumes(projected: Path, tmp_path: Path) -> None:
    record = json.loads((projected / "config.json").read_text())
    assert record["train"]["feature_projection"] == record["head"]["feature_projection"] == 8
    config = _config_of(projected)
    weight, bias = pca_projection(_training_features(config), 8)  # the training split's, refitted
    # the projected feature, and the action if it enters here
    inputs = 8 + (config.settings.head_form == "concat")
    assert config.head().input_dim == inputs
    for stem in ("best", "last"):
        saved = load_file(projected / f"{stem}.safetensors")
        assert saved["head.hidden.weight"].shape == (4096, inputs)
        assert torch.equal(saved["head.projection.weight"], weight)  # fitted once, never trained
        assert torch.equal(saved["head.projection.bias"], bias)
    assert json.loads((projected / "last.json").read_text())["epoch"] == 2  # resumed
    net, _ = load_qnet(projected)
    assert net.head.config.feature_projection == 8 and torch.equal(net.head.projection.weight, weight)

    # A checkpoint written before the field existed is unprojected: it loads and resumes as P = 0.
    plain = replace(config, feature_projection=0, epochs=1)
    old = train(plain, tmp_path / "old", progress=False)
    record = json.loads((old / "config.json").read_text())
    assert record["train"]["feature_projection"] == 0
    for block in ("train", "head"):
        del record[block]["feature_projection"]
    (old / "config.json").write_text(json.dumps(unchecked(record)))
    net, _ = load_qnet(old)
    assert net.head.projection is None and "head.projection.weight" not in load_file(old / "last.safetensors")
    train(replace(plain, epochs=2), old, progress=False)
    assert json.loads((old / "last.json").read_text())["epoch"] == 2


def _val_frames(data: Path, n: int) -> list[np.ndarray]:
    dataset = Dataset.open(data)
    frames: list[np.ndarray] = []
    for entry in dataset.entries("val"):
        with dataset.reader(entry) as reader:
            frames += [reader.image(t) for t in range(entry.n_frames)]
    return frames[:: max(1, len(frames) // n)][:n]


@pytest.mark.slow
def test_projected_heads_decide_in_batches_as_alone(projected: Path, small_dataset: Path) -> None:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as an evaluation's workers (docs/design.md#lockstep)
    try:
        trained = QNetPolicy.from_checkpoint(projected)
        policies = [trained]
        for kind, k in (("depth", 1), ("depth", 3), ("coll", 1)):  # the paper's size, untrained heads
            torch.manual_seed(0)
            head = build_head(paper_head(kind, 1280, lookahead=k, feature_projection=256))
            head.projection.weight.copy_(torch.randn(256, 1280) / 36)  # the kernels' bits, not PCA's
            head.projection.bias.copy_(torch.randn(256))
            policies.append(QNetPolicy(QNet(trained.net.trunk, head), kind))
        observations = [{"image": f} for f in _val_frames(small_dataset, BATCH_FRAMES + 3)]
        for policy in policies:
            assert_batch_decides_as_alone(policy, observations)
    finally:
        torch.set_num_threads(threads)


@pytest.mark.slow
def test_a_projected_net_exports_as_torch(projected: Path, small_dataset: Path, tmp_path: Path) -> None:
    for module in ("onnx", "onnxscript", "onnxruntime"):
        pytest.importorskip(module)
    from depthq.deploy.onnx_export import export_onnx
    from depthq.policies.onnx import OnnxPolicy

    onnx_policy = OnnxPolicy(export_onnx(projected, tmp_path / "onnx"))
    policy = QNetPolicy.from_checkpoint(projected)
    for frame in _val_frames(small_dataset, 5):
        np.testing.assert_allclose(onnx_policy.values(frame), policy.values(frame), atol=1e-4)
        assert onnx_policy.act({"image": frame}) == policy.act({"image": frame})
