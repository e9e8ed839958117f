"""The bootstrapped Depth-Q-Net target (docs/design.md#bootstrap): by hand on a tiny head, and a real
training on conftest's small dataset whose targets after the first epoch are bootstrapped. No mocks."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from paper_head import paper_head

from depthq.errors import ConfigError
from depthq.flags import build_config
from depthq.networks import DepthSettings, build_head
from depthq.train.bootstrap import bootstrapped_targets, greedy_bins
from depthq.train.config import TrainConfig
from depthq.train.trainer import train


def _head_with_bias(per_action: torch.Tensor) -> torch.nn.Module:
    """A per-action head whose bins are its output bias whatever the feature: (3, bins) for −1, 0, +1."""
    head = build_head(paper_head("depth", 4, hidden=2, n_bins=per_action.shape[1], form="per_action")).eval()
    with torch.no_grad():
        head.output.weight.zero_()
        head.output.bias.copy_(per_action.flatten())
    return head


def test_the_greedy_action_is_the_policys_and_ties_go_straight() -> None:
    features = torch.zeros(2, 4)
    head = _head_with_bias(torch.tensor([[1.0, 0.6], [0.5, 0.9], [0.0, 0.7]]))  # nearest: 0.6, 0.5, 0.7
    torch.testing.assert_close(greedy_bins(head, features), torch.tensor([[0.0, 0.7]] * 2))
    tied = _head_with_bias(torch.tensor([[0.8, 0.9], [0.8, 1.0], [0.8, 2.0]]))
    torch.testing.assert_close(greedy_bins(tied, features), torch.tensor([[0.8, 1.0]] * 2))


def test_the_bootstrapped_target_by_hand() -> None:
    head = _head_with_bias(torch.tensor([[0.3, 0.3], [1.5, 0.4], [0.2, 0.2]]))  # greedy: straight
    next_bins = torch.tensor([[1.0, math.nan], [0.2, 0.5]])
    target = bootstrapped_targets(next_bins, head, torch.zeros(2, 4), gamma=0.75)
    expected = torch.tensor([[0.25 * 1.0 + 0.75 * 1.0, math.nan], [0.2, 0.25 * 0.5 + 0.75 * 0.4]])
    torch.testing.assert_close(target, expected, equal_nan=True)
    same = bootstrapped_targets(next_bins, head, torch.zeros(2, 4), gamma=0.0)
    torch.testing.assert_close(same, next_bins, equal_nan=True)  # γ = 0: the one-step target


@pytest.mark.parametrize("changes", [
    {"depth.bootstrap": 1.0}, {"depth.bootstrap": -0.1}, {"depth.bootstrap": 0.5, "model": "coll"},
    {"depth.bootstrap": 0.5, "depth.lookahead": 2},
])
def test_bad_bootstrap_settings_are_refused_by_value(changes: dict) -> None:
    with pytest.raises(ConfigError, match="bootstrap"):
        build_config(TrainConfig, {"model": "depth", "data": "d", **changes})


@pytest.mark.slow
def test_a_bootstrapped_training_starts_as_the_plain_one_and_then_departs(
    small_dataset: Path, tmp_path: Path
) -> None:
    fast = {"model": "depth", "data": str(small_dataset), "epochs": 3, "train_batches": 4, "val_batches": 2,
            "batch_size": 16, "hidden": 64}
    plain = train(TrainConfig(**fast), tmp_path / "plain", progress=False)
    boot = train(TrainConfig(**fast, settings=DepthSettings(bootstrap=0.9)), tmp_path / "boot",
                 progress=False)
    config = json.loads((boot / "config.json").read_text())
    assert config["train"]["depth"]["bootstrap"] == 0.9 and config["head"]["hidden"] == 64
    assert "bootstrap" not in json.loads((plain / "config.json").read_text())["train"]["depth"]  # unset

    def losses(folder: Path) -> list[tuple[float, float]]:
        rows = [line.split(",") for line in (folder / "metrics.csv").read_text().splitlines()[1:]]
        return [(float(r[1]), float(r[2])) for r in rows]

    plain_losses, boot_losses = losses(plain), losses(boot)
    assert boot_losses[0] == plain_losses[0]  # epoch 1: no target network yet, the one-step targets
    assert np.isfinite(boot_losses).all()
    assert boot_losses[1] != plain_losses[1]  # from epoch 2 on the previous epoch's head bootstraps


@pytest.mark.slow
def test_a_depth_first_training_fits_both_parts_and_drives(small_dataset: Path, tmp_path: Path) -> None:
    config = TrainConfig(model="depth", data=str(small_dataset), epochs=4, train_batches=6, val_batches=2,
                         batch_size=16, hidden=64, settings=DepthSettings(head_form="depth_first"))
    folder = train(config, tmp_path / "df", progress=False)
    recorded = json.loads((folder / "config.json").read_text())
    assert recorded["head"]["form"] == recorded["train"]["depth"]["head_form"] == "depth_first"
    rows = [line.split(",") for line in (folder / "metrics.csv").read_text().splitlines()[1:]]
    train_losses = [float(r[1]) for r in rows]
    assert train_losses[-1] < train_losses[0]  # perception and dynamics both learn
    from depthq.policies.qnet import QNetPolicy

    policy = QNetPolicy.from_checkpoint(folder)
    frame = np.random.default_rng(0).integers(0, 256, (308, 410, 3), np.uint8)
    assert policy.act({"image": frame}) in (-1.0, 0.0, 1.0) and policy.last_values.shape == (3, 26)
    pytest.importorskip("onnxruntime")
    from depthq.deploy.onnx_export import export_onnx
    from depthq.policies.onnx import OnnxPolicy

    exported = OnnxPolicy(export_onnx(folder, tmp_path / "onnx"))  # the camera alone drives it
    assert exported.act({"image": frame}) == policy.act({"image": frame})
    np.testing.assert_allclose(exported.last_values, policy.last_values, atol=1e-5)
