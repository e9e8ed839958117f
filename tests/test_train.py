"""Training on a tiny real dataset (real MuJoCo runs, real EfficientNet-Lite0 weights, no mocks)."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import unchecked
from safetensors.torch import load, load_file, save

from depthq.blocks.optim import make_optimizer
from depthq.blocks.trunk import DEFAULT_TRUNK, build_trunk, preprocess
from depthq.checkpoint import load_qnet
from depthq.cli import main
from depthq.configio import read_json
from depthq.data.manifest import Dataset
from depthq.data.recorder import CollectConfig, collect, exploration_env
from depthq.data.samples import SampleConfig, bins_target
from depthq.data.views import FrameView, view_arrays
from depthq.errors import ConfigError, DataError
from depthq.flags import config_from_args
from depthq.networks import build_qnet
from depthq.policies.qnet import QNetPolicy
from depthq.scripts.train import add_arguments
from depthq.train.config import TrainConfig
from depthq.train.features import cache_dir, load_features
from depthq.train.samples import ImageSamples
from depthq.train.trainer import DivergedError, train

FAST = {"train_batches": 8, "val_batches": 2, "batch_size": 32}


@pytest.fixture
def data(small_dataset: Path) -> Path:
    """conftest's small dataset: 6 training runs (3 end in a bump) + 2 validation runs of ≤ 60 steps
    (the loss and over-fitting remarks below are about it), the default features cached (once)."""
    load_features(Dataset.open(small_dataset), DEFAULT_TRUNK, 128, progress=False)
    return small_dataset


def _config(data: Path, **kwargs: object) -> TrainConfig:
    return TrainConfig(**{"model": "depth", "data": str(data), "epochs": 4, **FAST, **kwargs})


def _metrics(out: Path) -> list[dict[str, str]]:
    lines = (out / "metrics.csv").read_text().splitlines()
    return [dict(zip(lines[0].split(","), line.split(","), strict=True)) for line in lines[1:]]


@pytest.mark.slow
@pytest.mark.parametrize("model", ["depth", "coll"])
def test_training_lowers_the_loss(data: Path, tmp_path: Path, model: str) -> None:
    # On this 6-run dataset Coll-Q-Net over-fits from epoch 1 at its default rate (0.1), and on the
    # column feature at any rate (validation BCE 0.535 → 0.537 at 0.001); the pooled feature at 0.01
    # shows it learning.
    changes = {"depth": {}, "coll": {"lr": 0.01, "trunk": "efficientnet_lite0"}}[model]
    out = train(_config(data, model=model, epochs=5, **changes), tmp_path / model, progress=False)
    rows = _metrics(out)
    assert [int(r["epoch"]) for r in rows] == list(range(1, 6))
    assert float(rows[-1]["train_loss"]) < float(rows[0]["train_loss"])
    assert min(float(r["val_loss"]) for r in rows[1:]) < float(rows[0]["val_loss"])
    record = read_json(out / "config.json")
    assert record["train"]["model"] == model
    assert record["learning_rate"] == {"depth": 0.1, "coll": 0.01}[model]
    assert read_json(out / "last.json")["epoch"] == 5
    assert any((out / "tb").iterdir())


@pytest.mark.slow
def test_resume_is_bit_identical_and_a_finished_run_is_a_no_op(data: Path, tmp_path: Path) -> None:
    whole = train(_config(data), tmp_path / "whole", progress=False)
    split = train(_config(data, epochs=2), tmp_path / "split", progress=False)
    assert read_json(split / "last.json")["epoch"] == 2
    train(_config(data), split, progress=False)  # resumes epochs 3 and 4
    for which in ("last", "best"):
        a, b = load_file(whole / f"{which}.safetensors"), load_file(split / f"{which}.safetensors")
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in _metrics(whole)]
    assert strip == [{k: v for k, v in r.items() if k != "seconds"} for r in _metrics(split)]

    stamp = (whole / "last.safetensors").stat().st_mtime_ns
    assert train(_config(data), whole, progress=False) == whole
    assert (whole / "last.safetensors").stat().st_mtime_ns == stamp


@pytest.mark.slow
def test_another_config_in_the_same_folder_is_refused(data: Path, tmp_path: Path) -> None:
    out = train(_config(data, epochs=1), tmp_path / "run", progress=False)
    with pytest.raises(ConfigError, match="batch_size"):
        train(_config(data, epochs=1, batch_size=16), out, progress=False)
    # A folder written before a field existed is not resumed under today's default for it.
    record = read_json(out / "config.json")
    del record["train"]["action_scale"]
    (out / "config.json").write_text(json.dumps(unchecked(record)))
    with pytest.raises(ConfigError, match="action_scale"):
        train(_config(data, epochs=1), out, progress=False)


@pytest.mark.slow
def test_checkpoint_loads_back(data: Path, tmp_path: Path) -> None:
    out = train(_config(data, epochs=2), tmp_path / "run", progress=False)
    net, record = load_qnet(out, "last", model="depth", trunk=DEFAULT_TRUNK)
    assert not net.training and record["trunk"] == DEFAULT_TRUNK
    saved = load_file(out / "last.safetensors")
    assert all(torch.equal(saved[f"head.{k}"], v) for k, v in net.head.state_dict().items())

    dataset = Dataset.open(data)
    entry = dataset.entries("val")[0]
    with dataset.reader(entry) as reader:
        image = preprocess(reader.image(3))
    actions = torch.tensor([-1.0, 0.0, 1.0])
    q = net.q_values(image, actions)
    assert torch.equal(q, load_qnet(out, "last")[0].q_values(image, actions))  # same net, same output
    table = load_features(dataset, DEFAULT_TRUNK, 128, progress=False)
    cached = torch.from_numpy(table.features[table.runs[entry.name][0] + 3].astype(np.float32))
    torch.testing.assert_close(net.q_values(cached, actions), q, atol=2e-2, rtol=1e-2)  # float16 cache


@pytest.mark.slow
def test_feature_cache_is_reused_and_invalidated(data: Path, tmp_path: Path) -> None:
    dataset = Dataset.open(data)
    index = cache_dir(data, DEFAULT_TRUNK, 128) / "index.json"
    stamp = index.stat().st_mtime_ns
    table = load_features(dataset, DEFAULT_TRUNK, 128, progress=False)
    assert not table.computed and index.stat().st_mtime_ns == stamp
    assert table.features.shape == (sum(e.n_frames for e in dataset.entries()), 1280)

    small = load_features(dataset, DEFAULT_TRUNK, 64, progress=False)
    assert small.computed and small.features.shape == table.features.shape
    assert not load_features(dataset, DEFAULT_TRUNK, 64, progress=False).computed

    changed = tmp_path / "changed"  # the same dataset with its last training run gone
    shutil.copytree(data, changed)
    manifest = json.loads((changed / "manifest.json").read_text())
    last = max(i for i, row in enumerate(manifest["runs"]) if row["split"] == "train")
    manifest["runs"].pop(last)
    (changed / "manifest.json").write_text(json.dumps(manifest))
    fewer = load_features(Dataset.open(changed), DEFAULT_TRUNK, 64, progress=False)
    assert fewer.computed and fewer.features.shape[0] < small.features.shape[0]
    np.testing.assert_array_equal(fewer.features[:100], small.features[:100])

    index.unlink()  # an interrupted computation leaves no index: never read as complete
    assert load_features(dataset, DEFAULT_TRUNK, 128, progress=False).computed


@pytest.mark.slow
def test_blocked_adadelta_equals_torch_adadelta() -> None:
    torch.manual_seed(0)
    head = TrainConfig(model="coll", data="-", trunk="mobilenet_v1_025").head()
    a, b = build_qnet(head, "mobilenet_v1_025"), build_qnet(head, "mobilenet_v1_025")
    b.load_state_dict(a.state_dict())
    opt_a, opt_b = torch.optim.Adadelta(make_optimizer(a, 0.1).param_groups), make_optimizer(b, 0.1)
    images, actions, target = torch.rand(4, 3, 64, 64), torch.rand(4), torch.tensor([0.0, 1.0, 0.0, 1.0])
    for model, opt in ((a, opt_a), (b, opt_b)):
        torch.manual_seed(1)  # the same dropout masks
        for _ in range(3):
            loss = torch.nn.functional.binary_cross_entropy_with_logits(model(images, actions), target)
            opt.zero_grad()
            loss.backward()
            opt.step()
    assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters(), strict=True))


@pytest.mark.slow
@pytest.mark.parametrize("trunk", ["mobilenet_v1_025", "efficientnet_lite0_columns_tuned"])
def test_trainable_trunk_trains_from_images(data: Path, tmp_path: Path, trunk: str) -> None:
    config = _config(data, trunk=trunk, epochs=1, train_batches=2, batch_size=8, input_size=64)
    out = train(config, tmp_path / trunk, progress=False)
    net, _ = load_qnet(out, "best")
    saved = load_file(out / "best.safetensors")
    assert not net.trunk.frozen and any(k.startswith("trunk.") for k in saved)
    torch.manual_seed(config.seed)  # as `train` does before building the network, trunk first
    start = build_trunk(trunk).state_dict()  # the training's start: ImageNet or the seed's random weights
    moved = [k for k, v in start.items() if v.is_floating_point() and not torch.equal(saved[f"trunk.{k}"], v)]
    assert moved, "the trunk's weights did not change in training"


@pytest.mark.slow
def test_image_samples_are_the_preprocessed_frames(data: Path) -> None:
    """Frames are decoded once and held as uint8; a batch must equal preprocessing its frames."""
    dataset = Dataset.open(data)
    view = FrameView(dataset, "train", view_arrays(dataset, "train", None, bins_target))
    samples = ImageSamples(view, 64)
    idx = torch.tensor([0, len(view) - 1, 7, 7])
    batch = samples.batch(idx)
    expected = preprocess(np.stack([view[i][0] for i in idx.tolist()]), 64)
    assert torch.equal(batch.inputs, expected)
    assert torch.equal(batch.targets, torch.from_numpy(view.arrays["target"][idx.numpy()]).float())


def test_default_learning_rates() -> None:
    """0.1 for both: the paper's 0.01 under-trains Coll-Q-Net in 40 epochs (docs/val_choices.md)."""
    assert TrainConfig(model="depth", data="d").learning_rate == 0.1
    assert TrainConfig(model="coll", data="d").learning_rate == 0.1
    assert TrainConfig(model="coll", data="d", lr=0.01).learning_rate == 0.01


def test_precision_is_a_validated_flag() -> None:
    with pytest.raises(ConfigError, match=r"precision.*'fp16'"):
        TrainConfig(model="depth", data="d", precision="fp16")
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--model", "depth", "--data", "d", "--out", "o", "--precision", "bf16"])
    assert config_from_args(TrainConfig, args).precision == "bf16"
    assert TrainConfig(model="depth", data="d").precision == "fp32"


@pytest.mark.slow
def test_bf16_training_is_recorded_deterministic_and_its_policy_decides_in_fp32(
    data: Path, tmp_path: Path
) -> None:
    a = train(_config(data, epochs=2, precision="bf16"), tmp_path / "a", progress=False)
    b = train(_config(data, epochs=2, precision="bf16"), tmp_path / "b", progress=False)
    fp32 = train(_config(data, epochs=2), tmp_path / "fp32", progress=False)
    assert read_json(a / "config.json")["train"]["precision"] == "bf16"
    assert read_json(fp32 / "config.json")["train"]["precision"] == "fp32"
    weights, again = load_file(a / "last.safetensors"), load_file(b / "last.safetensors")
    assert all(torch.equal(weights[k], again[k]) for k in weights)  # (the header's key order may differ)
    reference = load_file(fp32 / "last.safetensors")
    assert all(t.dtype == torch.float32 for t in weights.values())  # master weights stay float32
    assert any(not torch.equal(weights[k], reference[k]) for k in weights)  # bf16 did change the arithmetic
    bf16_val, fp32_val = (float(_metrics(out)[-1]["val_loss"]) for out in (a, fp32))
    assert bf16_val == pytest.approx(fp32_val, rel=0.1)
    policy = QNetPolicy.from_checkpoint(a)
    with Dataset.open(data).reader(Dataset.open(data).entries("val")[0]) as reader:
        values = policy.values(reader.image(3))
    assert values.dtype == np.float32 and np.isfinite(values).all()


@pytest.mark.slow
def test_benches_measure_each_precision(data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    def bench(*args: str) -> dict:
        assert main(["bench", *args, "--json"]) == 0
        return json.loads(capsys.readouterr().out.strip().splitlines()[-1])

    result = bench("train", "--precision", "fp32,bf16", "--seconds", "1", "--threads", "1")
    assert list(result["variants"]) == ["depth_first/fp32", "depth_first/bf16"] and result["threads"] == 1
    assert all(p["samples_per_s"] > 0 for p in result["variants"].values())
    assert result["samples_per_s"] == result["variants"]["depth_first/fp32"]["samples_per_s"]
    # The paper's head beside the default: the same 4096-wide first layer, the dynamics' is 27 wide.
    result = bench("train", "--head-form", "depth_first,concat", "--seconds", "1", "--threads", "1")
    forms = result["variants"]
    assert list(forms) == ["depth_first/fp32", "concat/fp32"]
    assert forms["depth_first/fp32"]["head_gflops"] / forms["depth_first/fp32"]["samples_per_s"] > (
        forms["concat/fp32"]["head_gflops"] / forms["concat/fp32"]["samples_per_s"])
    assert main(["bench", "train", "--head-form", "dueling", "--seconds", "1"]) == 2
    assert "dueling" in capsys.readouterr().err
    # Widths side by side: a narrower head does less work per sample, against the same matmul.
    widths = bench("train", "--hidden", "1024,4096", "--seconds", "1", "--threads", "1")["variants"]
    assert list(widths) == ["depth_first/fp32/1024", "depth_first/fp32/4096"]
    narrow, wide = widths.values()
    assert narrow["head_gflops"] / narrow["samples_per_s"] < wide["head_gflops"] / wide["samples_per_s"] / 3
    for bad in ("0", "wide"):
        assert main(["bench", "train", "--hidden", bad, "--seconds", "1"]) == 2
        assert bad in capsys.readouterr().err
    result = bench("features", "--data", str(data), "--frames", "32", "--precision", "bf16,fp32")
    assert list(result["precisions"]) == ["bf16", "fp32"]
    assert all(p["frames"] == 32 and p["frames_per_s"] > 0 for p in result["precisions"].values())
    assert main(["bench", "train", "--precision", "fp16", "--seconds", "1"]) == 2
    assert "fp16" in capsys.readouterr().err


@pytest.mark.slow
def test_a_checkpoint_older_than_precision_loads_and_resumes_as_fp32(data: Path, tmp_path: Path) -> None:
    out = train(_config(data, epochs=1), tmp_path / "old", progress=False)
    record = read_json(out / "config.json")
    del record["train"]["precision"]  # as written before the field existed
    (out / "config.json").write_text(json.dumps(unchecked(record)))
    assert QNetPolicy.from_checkpoint(out).kind == "depth"
    train(_config(data, epochs=2), out, progress=False)
    assert read_json(out / "last.json")["epoch"] == 2
    with pytest.raises(ConfigError, match="precision"):
        train(_config(data, epochs=3, precision="bf16"), out, progress=False)


@pytest.mark.slow
def test_bad_inputs(data: Path, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="'wall'"):
        TrainConfig(model="wall", data=str(data))
    with pytest.raises(ConfigError, match="epochs"):
        TrainConfig(model="depth", data=str(data), epochs=0)

    with pytest.raises(ConfigError, match="max_steps 25"):  # runs could never be long enough to count
        CollectConfig(max_steps=25)
    no_bumps = tmp_path / "no_bumps"  # seed 0, 2.9 s at 10 Hz: no run lasts long enough to bump
    config = CollectConfig(runs=2, val_runs=1, max_steps=29, env=exploration_env(10.0))
    collect(no_bumps, config, workers=1, progress=False)
    with pytest.raises(ConfigError, match="no run ended in a bump"):
        train(_config(no_bumps, model="coll", samples=SampleConfig(every_run_end=False)), tmp_path / "coll",
              progress=False)
    assert not (tmp_path / "coll").exists()

    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match=r"no config\.json"):
        load_qnet(tmp_path / "empty")
    with pytest.raises(ConfigError, match="no such checkpoint"):
        load_qnet(tmp_path / "missing")
    out = train(_config(data, epochs=1), tmp_path / "depth", progress=False)
    with pytest.raises(ConfigError, match="'coll'"):
        load_qnet(out, model="coll")
    record = read_json(out / "config.json")
    record["head"]["kind"] = "sonar"
    (out / "config.json").write_text(json.dumps(unchecked(record)))
    with pytest.raises(ConfigError, match="sonar"):
        load_qnet(out)


@pytest.mark.slow
def test_corrupted_weights_are_refused_by_name(data: Path, tmp_path: Path) -> None:
    # A checkpoint acting with its best weights, so that loading it by default reads best.safetensors.
    out = train(_config(data, epochs=1, weights="best"), tmp_path / "run", progress=False)
    policy_before = QNetPolicy.from_checkpoint(out)
    best = out / "best.safetensors"
    blob = bytearray(best.read_bytes())
    blob[-1000] ^= 0x01  # one bit of one weight
    best.write_bytes(bytes(blob))
    with pytest.raises(DataError, match=r"best\.safetensors: corrupted weights"):
        load_qnet(out)
    with pytest.raises(DataError, match=r"best\.safetensors: corrupted weights"):
        QNetPolicy.from_checkpoint(out)
    best.write_bytes(bytes(blob[: len(blob) // 2]))  # truncated
    with pytest.raises(DataError, match=r"best\.safetensors: not a readable safetensors"):
        load_qnet(out)

    state = out / "last_state.safetensors"  # a resume checks the digest too
    blob = bytearray(state.read_bytes())
    blob[-1000] ^= 0x01
    state.write_bytes(bytes(blob))
    with pytest.raises(DataError, match=r"last_state\.safetensors: corrupted weights"):
        train(_config(data, epochs=2, weights="best"), out, progress=False)

    last = out / "last.safetensors"  # a file from before digests were recorded: loads, with a warning
    tensors = load(last.read_bytes())  # a copy: load_file maps the file that is rewritten next
    last.write_bytes(save(tensors, metadata={"epoch": "1"}))
    with pytest.warns(UserWarning, match=r"last\.safetensors: no SHA-256 recorded"):
        net, _ = load_qnet(out, "last")
    head = net.head.state_dict()
    assert sorted(tensors) == sorted(f"head.{k}" for k in head)
    assert all(torch.equal(head[k[5:]], v) for k, v in tensors.items())
    assert policy_before.kind == "depth"


@pytest.mark.slow
def test_divergence_stops_with_a_clear_error(data: Path, tmp_path: Path) -> None:
    with pytest.raises(DivergedError, match=r"diverged.*no epoch finished"):
        train(_config(data, lr=1e30), tmp_path / "nan", progress=False)
    assert (tmp_path / "nan" / "config.json").is_file()
    assert not (tmp_path / "nan" / "last.safetensors").exists()
