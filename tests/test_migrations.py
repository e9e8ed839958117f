"""Every old on-disk shape still reads, through its version's migration (`depthq.blocks.migrations`):
a checkpoint's config.json of each format version, stored under tests/data/checkpoints as those
versions wrote it (configs only: the network is rebuilt from them, untrained), and the names sweeps
gave model folders before settings were renamed."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import pytest

from depthq.blocks.heads import HeadConfig
from depthq.checkpoint import (
    FORMAT_VERSION,
    PolicyRecord,
    dataset_record,
    policy_record,
    read_config,
)
from depthq.configio import from_dict
from depthq.errors import ConfigError
from depthq.networks import DepthSettings, build_head
from depthq.train.config import TrainConfig

STORED = Path(__file__).parent / "data"
OLD_DATA = "/nonexistent/depthq-old-data"  # the stored records' dataset: not found, as on another machine
# What a version 1 or 2 record, which records neither, was made for (the simulated camera, 4 Hz).
LEGACY_POLICY = PolicyRecord(decision_hz=4.0, frame_size=(308, 410), actions=(-1.0, 0.0, 1.0),
                             rule="farthest_nearest_bin", bins=None)
# The training every stored old record describes, as TrainConfig reads it today.
OLD_TRAIN = dict(model="depth", data=OLD_DATA, runs=200, seed=1, trunk="efficientnet_lite0", dropout=0.5,
                 settings=DepthSettings(depth_loss="valid_mean", head_form="concat"), average=0.0)


def _read(name: str, tmp_path: Path) -> dict:
    folder = tmp_path / name
    folder.mkdir()
    shutil.copy(STORED / "checkpoints" / f"{name}.json", folder / "config.json")
    return read_config(folder)


def _head(record: dict) -> HeadConfig:
    head = from_dict(HeadConfig, record["head"])
    build_head(head)  # the network it describes is built
    return head


def test_a_version_1_checkpoint_reads_as_today(tmp_path: Path) -> None:
    with pytest.warns(UserWarning, match="dataset not found; its decision rate is taken as 4 Hz"):
        record = _read("v1", tmp_path)
    assert record["format_version"] == FORMAT_VERSION
    assert from_dict(TrainConfig, record["train"]) == TrainConfig(**OLD_TRAIN, weights="best")
    assert _head(record) == HeadConfig("depth", 1280, hidden=4096, dropout=0.5, action_scale=1.0, lookahead=1,
                                       feature_projection=0, form="concat", output_bias=0.0,
                                       bin_gradient="relu")
    assert policy_record(record) == LEGACY_POLICY
    assert dataset_record(record).fingerprint is None and dataset_record(record).path == OLD_DATA


def test_a_version_2_checkpoint_reads_as_today(tmp_path: Path) -> None:
    with pytest.warns(UserWarning, match="dataset not found"):
        record = _read("v2", tmp_path)
    train = from_dict(TrainConfig, record["train"])
    assert train == TrainConfig(**OLD_TRAIN, action_scale=10.0, weights="best")
    assert _head(record).action_scale == 10.0
    assert policy_record(record) == LEGACY_POLICY
    assert dataset_record(record).fingerprint == "0" * 64 and "data_fingerprint" not in record


def test_a_version_3_checkpoint_written_before_33_reads_as_today(tmp_path: Path) -> None:
    """`train.select` and `policy.selection` under their new names, the sample settings in
    `train.samples`, the paper's head (no form recorded), the dataset's world naming its look."""
    record = _read("v3_before_33", tmp_path)
    train = from_dict(TrainConfig, record["train"])
    assert train == TrainConfig(**OLD_TRAIN, action_scale=10.0, weights="final", snapshots=(20,))
    assert "select" not in record["train"] and "horizon" not in record["train"]
    assert "depth_loss" not in record["train"] and record["train"]["depth"]["depth_loss"] == "valid_mean"
    assert _head(record).form == "concat"
    assert policy_record(record).rule == "farthest_nearest_bin" and "selection" not in record["policy"]
    world = dataset_record(record).env["world"]
    assert world["look"] == "flat" and "appearance" not in world


def test_a_version_3_checkpoint_written_before_56_reads_as_today(tmp_path: Path) -> None:
    """Before #56 every train record held Depth-Q-Net's own settings among the others: a Coll-Q-Net's,
    which meant nothing to it, are dropped (a Depth-Q-Net's move under "depth": v3_before_33's)."""
    record, today = _read("v3_before_56", tmp_path), _read("v3", tmp_path)
    assert {"lookahead", "head_form", "depth_loss"} <= set(json.loads(
        (STORED / "checkpoints" / "v3_before_56.json").read_text())["train"])
    assert record["train"] == {k: v for k, v in today["train"].items() if k != "coll"}
    assert from_dict(TrainConfig, record["train"]) == from_dict(TrainConfig, today["train"])


def test_a_version_3_checkpoint_written_today_reads_as_it_is(tmp_path: Path) -> None:
    stored = json.loads((STORED / "checkpoints" / "v3.json").read_text())
    record = _read("v3", tmp_path)
    assert record == {k: v for k, v in stored.items() if k != "sha256"}
    assert from_dict(TrainConfig, record["train"]).model == _head(record).kind == "coll"


def test_a_head_record_without_the_fields_added_since_reads_as_it_did(tmp_path: Path) -> None:
    """A checkpoint's "head" written before action_scale, lookahead, feature_projection, form, output_bias
    or bin_gradient (added in that order), or with form "concat" (left out of records until #33), reads
    as the defaults HeadConfig had then, in a version 1 record and a version 3 one alike."""
    from depthq.checkpoint import FORMAT

    stored = json.loads((STORED / "checkpoints" / "heads_before_their_fields.json").read_text())
    for n, case in enumerate(stored["cases"]):
        for version in (1, FORMAT_VERSION):
            folder = tmp_path / f"{n}-v{version}"
            folder.mkdir()
            (folder / "config.json").write_text(json.dumps({
                "format": FORMAT, "format_version": version, "train": {"model": "depth", "data": OLD_DATA},
                "head": case["head"],
            }))
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", ".*dataset not found")  # a version 1 record's: its rate
                record = read_config(folder)
            assert _head(record) == from_dict(HeadConfig, case["reads_as"]), (case["head"], version)


def test_sweep_model_folders_keep_the_names_settings_had() -> None:
    """A sweep of settings renamed since (select → weights, horizon → samples.horizon) names its model
    folders as the sweep did that stored them, under the old names or the new."""
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import parse_setting, widened

    stored = json.loads((STORED / "sweeps" / "models_before_33.json").read_text())
    for spelling in (stored["set"], stored["set_today"]):
        sweep = widened(get_preset("smoke"), grid=tuple(parse_setting(s) for s in spelling))
        assert sorted({m.name for m in sweep.models()}) == stored["models"], spelling


def test_a_sweep_folder_written_before_sweeps_is_claimed_by_its_preset(tmp_path: Path) -> None:
    """Its reproduce.json holds the smoke preset under "preset", without the canyon family (the paper's
    then): the smoke preset resumes the folder, another family's sweep is refused naming what differs."""
    from depthq.errors import ConfigError
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.stages import _claim
    from depthq.pipeline.sweep import retarget

    for name in ("smoke", "hard"):
        (tmp_path / name).mkdir()
        shutil.copy(STORED / "sweeps" / "reproduce_before_sweeps.json", tmp_path / name / "reproduce.json")
    _claim(tmp_path / "smoke", get_preset("smoke"))
    assert json.loads((tmp_path / "smoke" / "reproduce.json").read_text())["sweep"]["family"] == "paper"
    with pytest.raises(ConfigError, match=r"family 'paper' there, 'hard' here"):
        _claim(tmp_path / "hard", retarget(get_preset("smoke"), family="hard"))


def test_a_sweep_folder_that_recorded_the_default_budget_as_none_is_claimed(tmp_path: Path) -> None:
    """Before presets named their epochs (#56), quick and paper recorded none, the trainer's 40: a
    folder of then is resumed by its preset, and refused by a sweep of another budget."""
    from depthq.errors import ConfigError
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.stages import _claim
    from depthq.pipeline.sweep import widened

    quick = get_preset("quick")
    then = {"sweep": {**quick.record(), "epochs": None}}
    for name in ("quick", "longer"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "reproduce.json").write_text(json.dumps(then))
    _claim(tmp_path / "quick", quick)
    assert json.loads((tmp_path / "quick" / "reproduce.json").read_text())["sweep"]["epochs"] == 40
    with pytest.raises(ConfigError, match=r"epochs 40 there, 60 here"):
        _claim(tmp_path / "longer", widened(quick, train=(*quick.train, ("epochs", 60))))


def test_a_summary_written_before_networks_owned_their_acting_settings_reads(tmp_path: Path) -> None:
    """An evaluation's summary.json from before #56 held Depth-Q-Net's acting settings among the
    others (its "rule", "discount" and "switch"): they read as its own, under its name."""
    from depthq.configio import read_json, to_dict, write_json
    from depthq.evaluate.online import recorded_config
    from depthq.networks import Selection

    old = {"canyons": ["val:1000", "val:1001"], "time_limit_s": 5.0, "seed": 3, "weights": None,
           "decision_hz": 4.0, "lockstep": True, "rule": "farthest_nearest_bin", "discount": 0.8,
           "switch": True}
    write_json(tmp_path / "summary.json", {"config": old, "policy": {"policy": "DQN:depth_n3_s0"}})
    config = recorded_config(read_json(tmp_path / "summary.json"))
    assert config.acting["depth"] == Selection(rule="farthest_nearest_bin", discount=0.8, switch=True)
    assert (config.canyons, config.time_limit_s, config.seed) == (("val:1000", "val:1001"), 5.0, 3)
    today = to_dict(config)
    assert today["depth"] == {"rule": "farthest_nearest_bin", "discount": 0.8, "switch": True}
    assert recorded_config({"config": today}) == config  # a summary written today reads as it is
    with pytest.raises(ConfigError, match="unknown field"):  # a misspelt setting is still refused
        recorded_config({"config": {**old, "rules": "farthest_nearest_bin"}})
