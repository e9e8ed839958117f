"""The Depth-Q-Net that looks K steps ahead (docs/design.md#lookahead): targets over the horizon read
against the run files themselves, the head (K = 1 is the one-step head to the bit), the loss, the
selection over action sequences, and a K = 3 checkpoint trained, driven and exported. Real data
from conftest's small dataset, no mocks."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from conftest import unchecked
from paper_head import paper_head
from torch import nn

from depthq.blocks.losses import depth_l1_loss, lookahead_l1_loss
from depthq.control.action_selection import (
    ACTIONS,
    candidate_sequences,
    depth_scores,
    pick_best,
)
from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target, collision_target
from depthq.data.views import FrameView, view_arrays
from depthq.errors import ConfigError
from depthq.flags import build_config, config_from_args
from depthq.networks import DepthSettings, Selection, build_head, get_network
from depthq.train.config import TrainConfig

DEPTH = get_network("depth")

CONFIG = DataConfig()


def _stored(dataset: Dataset, split: str, index: int) -> tuple[np.ndarray, np.ndarray]:
    """A run's bins and commands, read from its HDF5 file directly (not through depthq's reader)."""
    with h5py.File(dataset.root / dataset.entry(split, index).file, "r") as f:
        return f["bins"][:], f["actions"][:]


@pytest.mark.parametrize("changes", [{}, {"every_run_end": False}, {"action_lag": 1}])
def test_targets_over_the_lookahead_are_the_stored_bins_shifted(small_dataset: Path, changes: dict) -> None:
    dataset, config, k = Dataset.open(small_dataset), replace(CONFIG, **changes), 3
    one = view_arrays(dataset, "train", None, bins_target, config)
    ahead = view_arrays(dataset, "train", None, bins_target, config, lookahead=k)
    # The same samples as the one-step view, whose targets and actions are step 1's.
    for key in ("run_index", "run_offsets", "run_id", "frame_id"):
        np.testing.assert_array_equal(ahead[key], one[key])
    np.testing.assert_array_equal(ahead["target"][:, 0], one["target"])
    np.testing.assert_array_equal(ahead["action"][:, 0], one["action"])
    samples = len(one["frame_id"])
    assert ahead["target"].shape == (samples, k, 26) and ahead["mask"].shape == (samples, k)
    lag, clip = config.action_lag, config.action_clip
    for r, index in enumerate(ahead["run_index"].tolist()):
        bins, commands = _stored(dataset, "train", index)
        n = len(bins)
        entry = dataset.entry("train", index)
        last = n - 1 - config.horizon if (config.every_run_end or entry.collision) else n - 1
        rows = range(ahead["run_offsets"][r], ahead["run_offsets"][r + 1])
        for i in rows:
            t = ahead["frame_id"][i]
            for step in range(1, k + 1):
                valid = t + step <= last
                assert ahead["mask"][i, step - 1] == valid
                if valid:
                    np.testing.assert_array_equal(ahead["target"][i, step - 1], bins[t + step])
                else:  # past the run's last usable frame: masked, no target
                    assert np.isnan(ahead["target"][i, step - 1]).all()
                command = commands[min(t + step - 1 - lag, n - 2)]  # the last command held past the end
                assert ahead["action"][i, step - 1] == np.clip(command, -clip, clip)
        # A run's last sample keeps its first step only; the one K − 1 before it keeps all K.
        np.testing.assert_array_equal(ahead["mask"][rows[-1]], [True, False, False])
        assert ahead["mask"][rows[-k]].all()


def test_a_view_refuses_a_bad_lookahead_by_value(small_dataset: Path) -> None:
    dataset = Dataset.open(small_dataset)
    with pytest.raises(ConfigError, match="lookahead must be an integer >= 1, got 0"):
        view_arrays(dataset, "train", None, bins_target, CONFIG, lookahead=0)
    with pytest.raises(ConfigError, match="its lookahead must be 1, got 3"):
        view_arrays(dataset, "train", None, collision_target, CONFIG, lookahead=3)
    arrays = view_arrays(dataset, "val", None, bins_target, CONFIG, lookahead=2)
    image, actions, targets = FrameView(dataset, "val", arrays)[0]
    assert image.dtype == np.uint8 and actions.shape == (2,) and targets.shape == (2, 26)


def _one_step_head_by_hand(feature_dim: int, seed: int) -> tuple[nn.Linear, nn.Linear]:
    """The paper's head as it was before lookaheads: FC 4096 on feature ⊕ action, FC 26, Glorot
    weights and zero biases, made in that order from the seed."""
    torch.manual_seed(seed)
    hidden, output = nn.Linear(feature_dim + 1, 4096), nn.Linear(4096, 26)
    for layer in (hidden, output):
        nn.init.xavier_uniform_(layer.weight)
        nn.init.zeros_(layer.bias)
    return hidden, output


def test_lookahead_one_is_the_one_step_head_to_the_bit() -> None:
    hidden, output = _one_step_head_by_hand(256, seed=7)
    torch.manual_seed(7)
    head = build_head(paper_head("depth", 256, dropout=0.0, action_scale=10.0, lookahead=1)).eval()
    state = head.state_dict()
    assert {k: tuple(v.shape) for k, v in state.items()} == {
        "hidden.weight": (4096, 257), "hidden.bias": (4096,), "output.weight": (26, 4096),
        "output.bias": (26,),
    }
    for name, layer in (("hidden", hidden), ("output", output)):
        assert torch.equal(state[f"{name}.weight"], layer.weight)
        assert torch.equal(state[f"{name}.bias"], layer.bias)
    feature, action = torch.randn(5, 256), torch.tensor([-1.0, 0.0, 1.0, 0.5, -0.2])
    by_hand = torch.relu(output(torch.relu(hidden(torch.cat([feature, 10.0 * action[:, None]], dim=1)))))
    with torch.no_grad():
        assert torch.equal(head(feature, action), by_hand)


def test_a_lookahead_head_takes_sequences_and_gives_every_step() -> None:
    torch.manual_seed(0)
    head = build_head(paper_head("depth", 64, hidden=32, lookahead=3))
    shapes = {k: tuple(v.shape) for k, v in head.state_dict().items()}
    assert shapes == {"hidden.weight": (32, 67), "hidden.bias": (32,), "output.weight": (78, 32),
                      "output.bias": (78,)}
    out = head(torch.randn(4, 64), torch.zeros(4, 3))
    assert out.shape == (4, 3, 26) and (out >= 0).all()
    with pytest.raises(ConfigError, match=r"expected action sequences \(B, 3\), got \(4,\)"):
        head(torch.randn(4, 64), torch.zeros(4))
    with pytest.raises(ConfigError, match="its lookahead must be 1, got 2"):
        build_head(paper_head("coll", 64, lookahead=2))
    with pytest.raises(ConfigError, match="lookahead must be a positive integer, got 0"):
        paper_head("depth", 64, lookahead=0)


@pytest.mark.parametrize("reduction", ["original", "valid_mean"])
def test_the_lookahead_loss_weighs_steps_and_skips_masked_ones(reduction: str) -> None:
    gen = torch.Generator().manual_seed(0)
    pred, target = torch.rand(6, 3, 26, generator=gen) * 2, torch.rand(6, 3, 26, generator=gen) * 2.2
    one = torch.ones(1)
    for got, want in zip(lookahead_l1_loss(pred[:, :1], target[:, :1], one, reduction=reduction),
                         depth_l1_loss(pred[:, 0], target[:, 0], reduction=reduction), strict=True):
        torch.testing.assert_close(got, want)  # K = 1: the one-step loss
    weights = torch.tensor([1.0, 0.5, 0.25])
    masked = target.clone()
    masked[0, 2] = math.nan  # sample 0's third step lies past its run's end
    loss, per_sample = lookahead_l1_loss(pred, masked, weights, reduction=reduction)
    steps = [depth_l1_loss(pred[:, k], masked[:, k], reduction=reduction)[1] for k in range(3)]
    if reduction == "original":  # each step's loss, weighted, over the weights of all K steps
        want = sum(w * s for w, s in zip(weights, steps, strict=True)) / weights.sum()
        torch.testing.assert_close(per_sample, want)
        torch.testing.assert_close(loss, want.mean())
        assert steps[2][0] == 0  # the masked step adds nothing
    else:  # weighted absolute errors over the weighted count of valid bins
        valid = torch.isfinite(masked) & (masked < 2.0 - 1e-6)
        sums = torch.where(valid, (pred - masked.nan_to_num()).abs(), 0.0).sum(dim=2) @ weights
        counts = valid.sum(dim=2).float() @ weights
        torch.testing.assert_close(per_sample, sums / counts)
        torch.testing.assert_close(loss, sums.sum() / counts.sum())
    with pytest.raises(ConfigError, match=r"3 steps but weights \(2,\)"):
        lookahead_l1_loss(pred, target, torch.ones(2), reduction=reduction)


def test_selection_at_lookahead_one_picks_what_the_one_step_rule_picks() -> None:
    rng = np.random.default_rng(0)
    for trial in range(300):
        pred = rng.uniform(0.3, 2.0, (3, 26))
        if trial % 3 == 0:  # ties and ReLU zeros, where the tie rule decides
            pred[rng.integers(3)] = pred[rng.integers(3)]
            pred[:, rng.integers(26)] = 0.0
        today = pick_best(depth_scores(pred), np.asarray(ACTIONS), True, DEPTH.tie_tol)
        assert DEPTH.choose(pred, np.asarray(ACTIONS)) == today
        for selection in (Selection(rule="farthest_nearest_bin"), Selection(switch=True)):
            sequences = candidate_sequences(ACTIONS, 1, selection.switch)
            assert DEPTH.choose(pred[:, None], sequences, selection) == today


def test_selection_over_sequences_min_or_discounted_first_action() -> None:
    held = candidate_sequences(ACTIONS, 3)
    np.testing.assert_array_equal(held, [[-1, -1, -1], [0, 0, 0], [1, 1, 1]])
    switched = candidate_sequences(ACTIONS, 3, switch=True)
    assert switched.shape == (3 + 2 * 6, 3) and [1.0, 1.0, -1.0] in switched.tolist()
    # Depth-Q-Net makes its candidates by its acting settings: held, or with `switch` switched too.
    np.testing.assert_array_equal(DEPTH.candidates(np.asarray(ACTIONS), 3, Selection()), held)
    np.testing.assert_array_equal(DEPTH.candidates(np.asarray(ACTIONS), 3, Selection(switch=True)), switched)
    pred = np.full((3, 3, 26), 1.5)
    pred[0, 0, 0] = 0.2  # right is close at t+1 only
    pred[1, 2, 10] = 0.4  # straight reaches a wall at t+3
    pred[2, :, 5] = 0.9  # left stays 0.9 m from something
    minimum = Selection(rule="farthest_nearest_bin")
    np.testing.assert_allclose(DEPTH.scores(pred, minimum), [0.2, 0.4, 0.9])
    assert DEPTH.choose(pred, held, minimum) == 1.0  # the farthest minimum over the steps: left
    assert DEPTH.choose(pred[:, :1], held[:, :1], minimum) == 0.0  # one step ahead: straight
    assert Selection().rule == "discounted_nearest_bin"  # the default, chosen on val canyons
    discounted = Selection(rule="discounted_nearest_bin", discount=0.5)
    w = np.array([1, 0.5, 0.25])
    np.testing.assert_allclose(DEPTH.scores(pred, discounted), [(0.2 + 0.75 + 0.375) / w.sum(),
                                                                   (1.5 + 0.75 + 0.1) / w.sum(), 0.9])
    assert DEPTH.choose(pred, held, discounted) == 0.0  # straight: the wall is far off
    with pytest.raises(ConfigError, match="got 'nearest'"):
        Selection(rule="nearest")
    with pytest.raises(ConfigError, match=r"discount must be in \(0, 1\], got 1\.5"):
        Selection(discount=1.5)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"depth.lookahead": 0}, "depth.lookahead must be an integer >= 1, got 0"),
        ({"depth.lookahead": 2.5}, "depth.lookahead must be an integer >= 1, got 2.5"),
        ({"model": "coll", "depth.lookahead": 3}, "depth.lookahead: a setting of model 'depth', not of"),
        ({"depth.lookahead": 15}, r"depth.lookahead 15 is more steps .* = 14\)"),
        ({"depth.lookahead_discount": 0}, r"depth.lookahead_discount must be in \(0, 1\], got 0"),
        ({"depth.lookahead_discount": 1.2}, r"depth.lookahead_discount must be in \(0, 1\], got 1.2"),
    ],
)
def test_bad_lookahead_settings_are_refused_by_value(changes: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        build_config(TrainConfig, {"model": "depth", "data": "data", **changes})


def test_train_flag_and_sweep_grid_take_the_lookahead() -> None:
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import parse_setting
    from depthq.scripts.train import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--model", "depth", "--data", "d", "--out", "o", "--depth.lookahead", "3",
                              "--depth.lookahead-discount", "0.9"])
    config = config_from_args(TrainConfig, args)
    assert (config.settings.lookahead, config.settings.step_weights()) == (3, (1.0, 0.9, 0.9**2))
    old = parser.parse_args(["--model", "depth", "--data", "d", "--out", "o", "--lookahead", "3"])
    assert config_from_args(TrainConfig, old).settings.lookahead == 3  # the flag by its old name

    assert parse_setting("depth.lookahead=1,3,5") == ("depth.lookahead", (1, 3, 5))
    assert parse_setting("lookahead=1,3,5") == ("depth.lookahead", (1, 3, 5))  # its old name
    sweep = replace(get_preset("smoke"), grid=(parse_setting("depth.lookahead=1,3,5"),))
    names = [m.name for m in sweep.models()]
    assert "depth_n3_s0" in names and "depth_n3_s0_lookahead3" in names and "depth_n6_s0_lookahead5" in names
    # Coll-Q-Net has no lookahead: each variant's row shows the one Coll-Q-Net, trained once.
    assert sorted(n for n in set(names) if n.startswith("coll")) == ["coll_n3_s0", "coll_n6_s0"]
    colls = [m for m in sweep.models() if m.net == "coll"]
    assert {sweep.train_config(m, "d").head().lookahead for m in colls} == {1} and len(colls) == 6


@pytest.mark.slow
def test_a_lookahead_checkpoint_trains_loads_drives_and_exports(small_dataset: Path, tmp_path: Path) -> None:
    from depthq.checkpoint import load_qnet
    from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
    from depthq.policies.qnet import QNetPolicy
    from depthq.policies.registry import make_policy
    from depthq.train.trainer import train

    fast = {"epochs": 2, "train_batches": 4, "val_batches": 1, "batch_size": 16}
    out = train(TrainConfig(model="depth", data=str(small_dataset), settings=DepthSettings(lookahead=3),
                            **fast), tmp_path / "k3", progress=False)
    record = json.loads((out / "config.json").read_text())
    assert record["train"]["depth"]["lookahead"] == record["head"]["lookahead"] == 3
    net, _ = load_qnet(out)
    assert net.head.config.lookahead == 3
    policy = QNetPolicy.from_checkpoint(out)
    frame = np.zeros((308, 410, 3), np.uint8)
    assert policy.values(frame).shape == (3, 3, 26)
    switching = make_policy(str(out), acting={"depth": Selection(rule="discounted_nearest_bin", switch=True)})
    assert switching.values(frame).shape == (15, 3, 26) and switching.act({"image": frame}) in ACTIONS
    from depthq.bench.policy import bench_policy

    timed = bench_policy([str(out)], decisions=2, batches=0, threads=1,
                         acting={"depth": Selection(switch=True)})["policies"][0]
    assert timed["candidates"] == 15 and timed["ms_median"] > 0  # the largest candidate set, timed
    assert switching.last_values.shape == (3, 26)  # what Fig. 4 draws: each held action at t+1

    config = EvalConfig(canyons=parse_canyon_set("val:1000"), time_limit_s=3.0)
    result = evaluate(str(out), tmp_path / "eval", config, workers=1, progress=False, video=False)
    assert result["summary"]["runs"] == 1 and result["policy"]["lookahead"] == 3
    assert (tmp_path / "eval" / "fig4_qualitative.png").is_file()  # Fig. 4: each held action at t+1
    offline = result["offline"]  # the first step's loss, and every step's
    assert offline["value"] == offline["steps"][0] and len(offline["steps"]) == 3

    # A checkpoint written before the field existed (and before Depth-Q-Net's settings had a block of
    # their own) is a one-step net: it loads and resumes as one.
    one = train(TrainConfig(model="depth", data=str(small_dataset), **{**fast, "epochs": 1}), tmp_path / "k1",
                progress=False)
    record = json.loads((one / "config.json").read_text())
    own = record["train"].pop("depth")
    record["train"].update({k: v for k, v in own.items() if k not in ("lookahead", "lookahead_discount")})
    del record["head"]["lookahead"]
    (one / "config.json").write_text(json.dumps(unchecked(record)))
    assert load_qnet(one)[0].head.config.lookahead == 1
    train(TrainConfig(model="depth", data=str(small_dataset), **fast), one, progress=False)  # epoch 2
    assert json.loads((one / "last.json").read_text())["epoch"] == 2

    pytest.importorskip("onnxruntime")
    from depthq.deploy.onnx_export import export_onnx
    from depthq.policies.onnx import OnnxPolicy

    path = export_onnx(out, tmp_path / "onnx")
    onnx_policy = OnnxPolicy(path)
    assert onnx_policy.lookahead == 3
    onnx_switching = OnnxPolicy(path, acting={"depth": switching.acting})  # 15 sequences through the graph
    np.testing.assert_allclose(onnx_switching.values(frame), switching.values(frame), atol=1e-4)
    with Dataset.open(small_dataset).reader(Dataset.open(small_dataset).entries("val")[0]) as reader:
        frames = [reader.image(t) for t in range(0, 20, 4)]
    for f in frames:
        np.testing.assert_allclose(onnx_policy.values(f), policy.values(f), atol=1e-4)
        assert onnx_policy.act({"image": f}) == policy.act({"image": f})


def test_evaluate_flags_choose_the_selection_rule_and_refuse_a_bad_one() -> None:
    """Depth-Q-Net's acting settings are `--depth.rule` ... (`--rule` ..., their old flags, too), stored
    under its name; a bad one is refused by its class, by its flag's path."""
    from depthq.configio import from_dict, to_dict
    from depthq.evaluate.online import EvalConfig
    from depthq.scripts.drive import add_arguments as add_drive_arguments
    from depthq.scripts.evaluate import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert "--depth.rule {farthest_nearest_bin,discounted_nearest_bin}, --rule" in parser.format_help()
    for given in (["--depth.rule", "farthest_nearest_bin", "--depth.discount", "0.8", "--depth.switch"],
                  ["--rule", "farthest_nearest_bin", "--discount", "0.8", "--switch"]):
        args = parser.parse_args(["pol", "--out", "o", *given])
        config = config_from_args(EvalConfig, args, canyons=("val:1000",))
        assert config.acting["depth"] == Selection(rule="farthest_nearest_bin", discount=0.8, switch=True)
        assert to_dict(config)["depth"] == {"rule": "farthest_nearest_bin", "discount": 0.8, "switch": True}
        assert from_dict(EvalConfig, to_dict(config)) == config and "rule" not in to_dict(config)
    drive = argparse.ArgumentParser()
    add_drive_arguments(drive)
    args = drive.parse_args(["--out", "o", "--rule", "farthest_nearest_bin"])
    acting = config_from_args(EvalConfig, args, canyons=("val:1000",)).acting
    assert acting["depth"].rule == "farthest_nearest_bin"
    assert EvalConfig().acting == {"depth": Selection()}  # each network's that has some, at its defaults
    with pytest.raises(ConfigError, match=r"depth\.rule must be one of .*, got 'nearest'"):
        build_config(EvalConfig, {"depth.rule": "nearest"})
    with pytest.raises(ConfigError, match=r"depth\.discount must be in \(0, 1\], got 0"):
        build_config(EvalConfig, {"depth.discount": 0})
    with pytest.raises(ConfigError, match=r"'coll' has no settings here"):
        EvalConfig(acting={"coll": Selection()})
