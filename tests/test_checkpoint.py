"""Checkpoints that describe themselves (a policy needs nothing but the folder), the format's
versions, and which weights a policy uses (`weights`, snapshots). Real MuJoCo runs, real trainings of
a few batches, no mocks."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import onnx
import pytest
import torch
from conftest import unchecked
from safetensors.torch import load_file

from depthq.checkpoint import FORMAT_VERSION, TrainingCheckpoint, TrainState, load_qnet, read_config
from depthq.cli import main
from depthq.configio import read_json
from depthq.data.manifest import Dataset
from depthq.data.samples import SampleConfig
from depthq.errors import ConfigError
from depthq.evaluate.online import EvalConfig, at_policy_rate, default_canyons, evaluate
from depthq.networks import DepthSettings
from depthq.policies.qnet import QNetPolicy
from depthq.policies.spec import PolicySpec
from depthq.sim.world import DEFAULT_DECISION_HZ
from depthq.train.config import TrainConfig
from depthq.train.trainer import train

FAST = {"train_batches": 1, "val_batches": 1, "batch_size": 16}  # an Adadelta step of the head: ≈ 0.5 s


@pytest.fixture
def data(small_dataset: Path) -> Path:
    """conftest's small dataset (6 + 2 runs at the default rate, features cached); never changed."""
    return small_dataset


CONCAT = DepthSettings(head_form="concat")  # the paper's head


def _config(data: Path, **kwargs: object) -> TrainConfig:
    return TrainConfig(**{"model": "depth", "data": str(data), "epochs": 2, **FAST, **kwargs})


def _tensors(path: Path) -> dict[str, torch.Tensor]:
    return dict(load_file(path))


def _equal(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.slow
def test_a_moved_checkpoint_without_its_data_evaluates_drives_exports_and_benches(
    data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b, c = (tmp_path / name for name in "abc")
    shutil.copytree(data, a / "data")
    monkeypatch.chdir(a)
    assert main(["train", "--model", "depth", "--data", "data", "--epochs", "1", "--train-batches", "2",
                 "--val-batches", "1", "--batch-size", "16", "--out", "ckpt", "--no-progress"]) == 0
    record = read_json(a / "ckpt" / "config.json")
    assert record["format_version"] == FORMAT_VERSION == 3
    assert record["dataset"]["path"] == str((a / "data").resolve())
    assert record["dataset"]["env"] == Dataset.open(data).config["env"]  # the manifest's, verbatim
    policy = record["policy"]
    assert (policy["decision_hz"], policy["frame_size"]) == (DEFAULT_DECISION_HZ, [308, 410])
    assert policy["actions"] == [-1, 0, 1] and policy["rule"] == "farthest_nearest_bin"
    assert policy["bins"]["clip"] == 2.0
    # The default Depth-Q-Net: the depth-first head, acting with its last quarter's weight average
    # (of 1 epoch: its last); all recorded.
    assert (record["train"]["depth"]["head_form"], record["head"]["form"]) == ("depth_first", "depth_first")
    assert (record["train"]["average"], record["train"]["weights"]) == (0.25, "average")
    assert record["provenance"]["package"] == "depthq"
    assert _equal(_tensors(a / "ckpt" / "average.safetensors"), _tensors(a / "ckpt" / "last.safetensors"))

    b.mkdir()
    shutil.move(a / "ckpt", b / "ckpt")
    shutil.rmtree(a / "data")
    # As if trained on 5 Hz data of the hard family: what a policy drives at, and where by default,
    # must come from the checkpoint.
    record["policy"]["decision_hz"] = HZ = 5.0
    record["dataset"]["env"]["world"]["family"] = "hard"
    (b / "ckpt" / "config.json").write_text(json.dumps(unchecked(record)))
    ckpt = str(b / "ckpt")
    c.mkdir()
    monkeypatch.chdir(c)
    capsys.readouterr()
    assert main(["evaluate", ckpt, "--canyons", "eval:0", "--time-limit", "2", "--workers", "1",
                 "--no-video", "--out", "eval"]) == 0
    assert "offline metrics skipped: its dataset is not found" in capsys.readouterr().err
    summary = read_json(c / "eval" / "summary.json")
    assert summary["config"]["decision_hz"] == HZ and "offline" not in summary
    assert summary["runs"][0]["steps"] <= 2 * HZ and summary["policy"]["weights"] == "average"

    assert main(["drive", "--policy", ckpt, "--canyon", "eval:0", "--time-limit", "2", "--frames", "2",
                 "--out", "drive", "--json"]) == 0
    drive = json.loads(capsys.readouterr().out)
    last_frame = max(int(p.stem.split("_")[1]) for p in (c / "drive").glob("frame_*.png"))
    assert last_frame == round(drive["time"] * HZ) > 0  # one decision (and frame) every 0.2 s

    assert main(["export", ckpt, "--out", "onnx"]) == 0
    meta = {p.key: p.value for p in onnx.load(c / "onnx" / "ckpt.onnx").metadata_props}
    assert json.loads(meta["depthq.frame_size"]) == [308, 410]
    assert json.loads(meta["depthq.actions"]) == [-1.0, 0.0, 1.0]
    # The exported graph evaluates at the rate its metadata records, as the checkpoint does; --hz wins.
    graph = f"onnx:{c / 'onnx' / 'ckpt.onnx'}"
    onnx_spec, ckpt_spec = PolicySpec.parse(graph), PolicySpec.parse(ckpt)
    assert at_policy_rate(EvalConfig(canyons=("eval:0",), decision_hz=10.0), onnx_spec).decision_hz == 10.0
    assert default_canyons(onnx_spec) == default_canyons(ckpt_spec) == "hard/eval"  # its data's family
    assert main(["evaluate", graph, "--canyons", "eval:0", "--time-limit", "2", "--workers", "1",
                 "--no-video", "--out", "eval-onnx"]) == 0
    summary = read_json(c / "eval-onnx" / "summary.json")
    assert summary["config"]["decision_hz"] == HZ and summary["runs"][0]["steps"] <= 2 * HZ

    assert main(["bench", "policy", "--policy", ckpt, "--decisions", "3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["policies"][0]["policy"] == "DQN:ckpt"

    # The data given back by hand: the same runs give the offline metric, other runs are refused.
    other = tmp_path / "other"
    shutil.copytree(data, other, ignore=shutil.ignore_patterns("features"))
    manifest = read_json(other / "manifest.json")
    manifest["runs"] = manifest["runs"][1:]
    (other / "manifest.json").write_text(json.dumps(manifest))
    assert main(["evaluate", ckpt, "--data", str(other), "--canyons", "eval:0", "--out", "refused"]) == 2
    err = capsys.readouterr().err
    assert f"--data {other}: not the dataset this checkpoint was trained on" in err
    assert not (c / "refused").exists()
    assert main(["evaluate", ckpt, "--data", str(data), "--canyons", "eval:0", "--time-limit", "1",
                 "--workers", "1", "--no-video", "--out", "with-data"]) == 0
    assert read_json(c / "with-data" / "summary.json")["offline"]["metric"] == "abs_diff"


@pytest.mark.slow
def test_a_future_format_is_refused_and_an_old_one_loads(data: Path, tmp_path: Path) -> None:
    # The paper's head: the only one a checkpoint of an older format can hold.
    out = train(_config(data, epochs=1, settings=CONCAT), tmp_path / "run", progress=False)
    assert read_json(out / "config.json")["train"]["weights"] == "best"
    record = read_json(out / "config.json")

    future = tmp_path / "future"
    shutil.copytree(out, future)
    (future / "config.json").write_text(json.dumps(unchecked({**record, "format_version": 7})))
    with pytest.raises(ConfigError, match=r"future/config\.json: checkpoint format version 7, .* 1 to 3"):
        load_qnet(future)
    assert main(["export", str(future), "--out", str(tmp_path / "onnx")]) == 2

    # A sweep finds a finished folder trained otherwise than the model of that name now means (the
    # paper's head, before the depth-first head became the default): an error, not a reused model.
    from depthq.pipeline.stages import _trained
    with pytest.raises(ConfigError, match=r"differs in: average, depth\.head_form, weights"):
        _trained(_config(data, epochs=1), out)
    assert _trained(_config(data, epochs=1, settings=CONCAT), out)

    # Version 3 before `head_form` was recorded (and Depth-Q-Net's settings were among the others, #56):
    # the paper's head, its best weights.
    before = tmp_path / "v3"
    shutil.copytree(out, before)
    flat_own = {k: v for k, v in record["train"]["depth"].items() if k != "head_form"}
    v3 = {**record, "train": {k: v for k, v in record["train"].items() if k != "depth"} | flat_own}
    v3["head"] = {k: v for k, v in record["head"].items() if k != "form"}
    (before / "config.json").write_text(json.dumps(unchecked(v3)))
    assert read_config(before)["train"] == record["train"]
    assert load_qnet(before)[0].head.config.form == "concat"

    # Version 3 before #33's renames (`train.select`, `policy.selection`): read under the new names,
    # its policy acts with the weights it chose, it resumes, and a sweep reuses it.
    renamed = tmp_path / "v3-select"
    shutil.copytree(out, renamed)
    old_train = {("select" if k == "weights" else k): v for k, v in record["train"].items()}
    old_policy = {("selection" if k == "rule" else k): v for k, v in record["policy"].items()}
    old_names = {**record, "train": {**old_train, "select": "final"}, "policy": old_policy}
    (renamed / "config.json").write_text(json.dumps(unchecked(old_names)))
    upgraded = read_config(renamed)
    assert upgraded["train"] == {**record["train"], "weights": "final"}
    assert upgraded["policy"] == record["policy"]
    head = {f"head.{k}": v for k, v in QNetPolicy.from_checkpoint(renamed).net.head.state_dict().items()}
    assert _equal(head, _tensors(renamed / "last.safetensors"))
    assert _trained(_config(data, epochs=1, settings=CONCAT, weights="final"), renamed)
    resumed = train(_config(data, epochs=2, settings=CONCAT, weights="final"), renamed, progress=False)
    assert resumed == renamed
    assert read_json(renamed / "config.json")["train"]["weights"] == "final"

    # Version 3 before #33 nested TrainConfig's sample settings in `train.samples`: read there, so a
    # sweep reuses the folder, and a training whose samples differ is told which setting differs.
    flat = tmp_path / "v3-flat"
    shutil.copytree(out, flat)
    flat_train = {k: v for k, v in record["train"].items() if k != "samples"} | record["train"]["samples"]
    assert "horizon" in flat_train and "samples" not in flat_train
    (flat / "config.json").write_text(json.dumps(unchecked({**record, "train": flat_train})))
    assert read_config(flat)["train"] == record["train"]
    assert load_qnet(flat)[1]["train"]["samples"]["horizon"] == 5
    assert _trained(_config(data, epochs=1, settings=CONCAT), flat)
    with pytest.raises(ConfigError, match=r"differs in: samples\.horizon\)"):
        _trained(_config(data, epochs=1, settings=CONCAT, samples=SampleConfig(horizon=3)), flat)

    # Version 2, the layout before `dataset` and `policy`: its rate from its dataset's manifest.
    old = tmp_path / "v2"
    shutil.copytree(out, old)
    v2 = {k: v for k, v in record.items() if k not in ("dataset", "policy")}
    v2["train"] = {k: v for k, v in record["train"].items() if k not in ("weights", "snapshots")}
    (old / "config.json").write_text(json.dumps(unchecked(
        {**v2, "format_version": 2, "data_fingerprint": record["dataset"]["fingerprint"]}
    )))
    net, upgraded = load_qnet(old)
    assert upgraded["policy"] == record["policy"] and upgraded["train"] == record["train"]
    head = {f"head.{k}": v for k, v in net.head.state_dict().items()}
    assert _equal(_tensors(old / "best.safetensors"), head)
    assert train(_config(data, epochs=2, settings=CONCAT), old, progress=False) == old  # resumed
    assert read_json(old / "config.json")["format_version"] == 3


@pytest.mark.slow
def test_weights_final_makes_a_policy_use_the_final_weights(data: Path, tmp_path: Path) -> None:
    # Coll-Q-Net at its default rate over-fits this tiny dataset from the first epoch: best ≠ final.
    out = train(_config(data, model="coll", epochs=3, weights="final"), tmp_path / "coll", progress=False)
    assert read_json(out / "best.json")["epoch"] < 3 == read_json(out / "last.json")["epoch"]
    best, last = _tensors(out / "best.safetensors"), _tensors(out / "last.safetensors")
    assert not _equal(best, last)
    head = {f"head.{k}": v for k, v in QNetPolicy.from_checkpoint(out).net.head.state_dict().items()}
    assert _equal(head, last)
    head = {f"head.{k}": v for k, v in QNetPolicy.from_checkpoint(out, "best").net.head.state_dict().items()}
    assert _equal(head, best)  # evaluate --weights overrides

    config = EvalConfig(canyons=("eval:0",), time_limit_s=1.0)
    summary = evaluate(str(out), tmp_path / "eval", config, workers=1, progress=False, video=False)
    assert summary["policy"]["weights"] == "last" and summary["offline"]["weights"] == "last"
    assert read_config(out)["train"]["weights"] == "final"


@pytest.mark.slow
def test_snapshots_are_kept_loadable_and_survive_a_resume(data: Path, tmp_path: Path) -> None:
    whole = train(_config(data, epochs=4, snapshots=(1, 3)), tmp_path / "whole", progress=False)
    assert sorted(p.name for p in whole.glob("epoch_*")) == [
        "epoch_0001.json", "epoch_0001.safetensors", "epoch_0003.json", "epoch_0003.safetensors"
    ]
    net, _ = load_qnet(whole, "epoch:3")
    head = {f"head.{k}": v for k, v in net.head.state_dict().items()}
    assert _equal(head, _tensors(whole / "epoch_0003.safetensors"))
    assert read_json(whole / "epoch_0003.json")["epoch"] == 3
    with pytest.raises(ConfigError, match=r"no epoch_0002\.safetensors .* snapshots are at epochs \[1, 3\]"):
        load_qnet(whole, "epoch:2")

    split = train(_config(data, epochs=2, snapshots=(1,)), tmp_path / "split", progress=False)
    train(_config(data, epochs=4, snapshots=(1, 3)), split, progress=False)  # resumes epochs 3 and 4
    for name in ("epoch_0001", "epoch_0003", "last"):
        assert _equal(_tensors(whole / f"{name}.safetensors"), _tensors(split / f"{name}.safetensors"))
    with pytest.raises(ConfigError, match=r"snapshots at epochs \[2\] asked for, but its training is past"):
        train(_config(data, epochs=4, snapshots=(2, 3)), split, progress=False)


@pytest.mark.slow
def test_the_weight_average_is_the_mean_of_the_last_epochs_and_survives_a_resume(
    data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = _config(data, epochs=4, snapshots=(2, 3, 4), average=0.75)  # epochs 2, 3 and 4
    whole = train(config, tmp_path / "whole", progress=False)
    snaps = [_tensors(whole / f"epoch_000{e}.safetensors") for e in (2, 3, 4)]
    mean = _tensors(whole / "average.safetensors")
    assert mean.keys() == snaps[0].keys()
    for key, value in mean.items():
        if value.is_floating_point():
            torch.testing.assert_close(value, sum(s[key] for s in snaps) / 3)
    assert not _equal(mean, snaps[-1])
    record = read_json(whole / "average.json")  # and the mean's validation loss, its own
    assert (record["epochs"], record["count"]) == ([2, 4], 3)
    assert record["val_loss"] > 0 and record["val_loss"] != read_json(whole / "last.json")["val_loss"]
    net, _ = load_qnet(whole, "average")
    assert _equal({f"head.{k}": v for k, v in net.head.state_dict().items()}, mean)

    split = tmp_path / "split"  # interrupted inside the window (after epoch 3's checkpoint), then resumed
    write_epoch = TrainingCheckpoint.write_epoch

    def interrupted(self: TrainingCheckpoint, model: object, optimizer: object, rng: object,
                    state: TrainState, *args: object, **kwargs: object) -> None:
        write_epoch(self, model, optimizer, rng, state, *args, **kwargs)
        if state.epoch == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(TrainingCheckpoint, "write_epoch", interrupted)
    with pytest.raises(KeyboardInterrupt):
        train(config, split, progress=False)
    monkeypatch.undo()
    assert read_json(split / "average.json")["epochs"] == [2, 3]
    with pytest.raises(ConfigError, match=r"inside a weight average from epoch 3, but the state holds one"):
        train(_config(data, epochs=8, snapshots=(2, 3, 4), average=0.75), split, progress=False)
    train(config, split, progress=False)
    assert _equal(_tensors(split / "average.safetensors"), mean)
    assert read_json(split / "average.json") == record
    with pytest.raises(ConfigError, match=r"no average\.safetensors .* without train\.average"):
        load_qnet(train(_config(data, epochs=1, average=0), tmp_path / "plain", progress=False), "average")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"average": 1.5}, r"train\.average must be a fraction of the epochs in \[0, 1\] .*got 1\.5"),
        ({"average": -1}, r"train\.average must be .*, got -1"),
        ({"weights": "average", "average": 0}, r"'average' needs a weight average"),
        ({"snapshots": (0,)}, "epoch 0 is not one of"),
        ({"snapshots": (5,)}, r"epoch 5 is not one of this training's epochs 1\.\.2"),
        ({"snapshots": (1, 1)}, r"repeats epoch\(s\) \[1\]"),
        ({"weights": "worst"}, "'worst'"),
    ],
)
def test_bad_weights_or_snapshots_are_refused_by_name(change: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        TrainConfig(model="depth", data="data", epochs=2, **change)
    with pytest.raises(ConfigError, match="'epoch:x'"):
        EvalConfig(weights="epoch:x")


def test_a_sweep_varies_weights_and_snapshots() -> None:
    from dataclasses import replace

    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import parse_setting

    assert parse_setting("weights=final") == parse_setting("select=final") == ("weights", ("final",))
    assert parse_setting("snapshots=40,20+40") == ("snapshots", ((40,), (20, 40)))
    grid = (parse_setting("weights=final"), parse_setting("epochs=3"), parse_setting("snapshots=1+2"))
    sweep = replace(get_preset("smoke"), grid=grid)
    depth, coll = sweep.models()[:2]
    # A setting names a model where it differs from that network's own default: a depth-first
    # Depth-Q-Net acts with its weight average unless told, a Coll-Q-Net with its best weights.
    assert (depth.net, coll.net) == ("depth", "coll")
    assert depth.name == "depth_n3_s0_selectfinal_epochs3_snapshots1+2"
    # The setting was called `select` when sweeps first named folders after it: they keep its name.
    assert coll.name == "coll_n3_s0_selectfinal_epochs3_snapshots1+2"
    for model in (depth, coll):
        config = sweep.train_config(model, "data")
        assert (config.weights, config.epochs, config.snapshots) == ("final", 3, (1, 2))
    best = replace(sweep, grid=(parse_setting("weights=best"),)).models()[0]
    assert best.name == "depth_n3_s0_selectbest"
    with pytest.raises(ConfigError, match=r"epoch 4 is not one of this training's epochs 1\.\.3"):
        replace(sweep, grid=(*grid[:2], parse_setting("snapshots=4")))
