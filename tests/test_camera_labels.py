"""Camera labels (issue #32): a labeller learnt on one canyon family's LiDAR labels the other family's
runs; the labels live in the run files, read back, train a Depth-Q-Net, and `dataset stats` rates them."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import unchecked
from safetensors.torch import load_file

from depthq.checkpoint import read_config
from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.data.runfile import file_sha256, write_labelled
from depthq.data.samples import bins_target
from depthq.data.views import view_arrays
from depthq.errors import ConfigError, DataError
from depthq.labellers.labeller import (
    CONFIG,
    WEIGHTS,
    LabellerConfig,
    label_dataset,
    load_labeller,
    train_labeller,
)
from depthq.train.config import TrainConfig

TOY_LABELLER = {"method": "perception", "hidden": 64, "steps": 40, "batch_size": 16, "lr": 1.0,
                "input_size": 64}
TOY_TRAINING = {"epochs": 2, "train_batches": 4, "val_batches": 1, "batch_size": 16}


@pytest.fixture(scope="module")
def labeller(small_hard_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A toy labeller learnt on the hard family's LiDAR."""
    config = LabellerConfig(data=str(small_hard_dataset), **TOY_LABELLER)
    return train_labeller(config, tmp_path_factory.mktemp("labeller") / "hard", progress=False, device="cpu")


@pytest.fixture(scope="module")
def labelled(small_dataset: Path, labeller: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the paper-family dataset with the hard labeller's camera labels, written by the verb."""
    root = tmp_path_factory.mktemp("labelled") / "data"
    shutil.copytree(small_dataset, root, ignore=shutil.ignore_patterns("features"))
    assert main(["label", str(root), "--from", "camera", "--labeller", str(labeller), "--no-progress"]) == 0
    return root


def _state(root: Path) -> dict[str, str]:
    """Every file of a dataset folder but its feature cache, by its SHA-256."""
    return {str(p.relative_to(root)): file_sha256(p) for p in sorted(root.rglob("*"))
            if p.is_file() and "features" not in p.parts}


@pytest.mark.slow  # the labeller's training and a labelling: fixtures of ~16 s
def test_the_labeller_learns_the_current_bins_from_real_frames(labeller: Path) -> None:
    record = json.loads((labeller / CONFIG).read_text())
    assert record["losses"][-1] < record["losses"][0]  # L1 on the hard family's current LiDAR bins
    assert record["source"]["family"] == "hard" and record["n_bins"] == 26
    names = {f"{layer}.{p}" for layer in ("hidden", "current") for p in ("weight", "bias")}
    assert set(load_file(labeller / WEIGHTS)) == names  # safetensors: never a pickle
    assert load_labeller(labeller).fingerprint == record["fingerprint"]
    again = LabellerConfig(data=record["config"]["data"], **TOY_LABELLER)
    assert train_labeller(again, labeller, progress=False) == labeller  # a finished folder is kept


@pytest.mark.slow  # the labeller's training and a labelling: fixtures of ~16 s
def test_labels_are_written_read_back_and_resumed(labelled: Path, small_dataset: Path, labeller: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    dataset, original, model = Dataset.open(labelled), Dataset.open(small_dataset), load_labeller(labeller)
    assert not dataset.verify()
    for entry in dataset.entries():
        old = original.entry(entry.split, entry.index)
        with dataset.reader(entry) as reader:
            run = reader.run(images=entry == dataset.entries()[0])
            assert run.camera is not None and run.camera.fingerprint == model.fingerprint
            assert ((run.camera.bins >= 0) & (run.camera.bins <= 2)).all() and run.camera.bins.shape == (
                entry.n_frames, 26)
            assert np.array_equal(run.bins, original.read_run(old, images=False).bins, equal_nan=True)
            if run.images is not None:  # read back: the labeller's estimates, bit for bit
                assert run.camera.bins.tobytes() == model.estimate(run).tobytes()
            # without its labels, the labelled file is the recorded one, byte for byte
            assert write_labelled(labelled / "stripped.h5", reader, None) == old.info
    (labelled / "stripped.h5").unlink()
    before = _state(labelled)
    argv = ["label", str(labelled), "--from", "camera", "--labeller", str(labeller), "--no-progress"]
    assert main(argv) == 0
    n = len(dataset.entries())
    assert f"written in 0 runs, {n} already there" in capsys.readouterr().out and _state(labelled) == before


@pytest.mark.slow
def test_a_labelling_stopped_before_its_manifest_is_resumed(labelled: Path, small_dataset: Path,
                                                            labeller: Path, tmp_path: Path) -> None:
    root = tmp_path / "data"
    shutil.copytree(small_dataset, root, ignore=shutil.ignore_patterns("features"))
    dataset, model = Dataset.open(root), load_labeller(labeller)
    entry = dataset.entries()[0]
    with dataset.reader(entry) as reader:  # the file renamed, the manifest not yet written
        write_labelled(dataset.path(entry), reader, model.label(reader))
    assert label_dataset(Dataset.open(root), model, progress=False) == (len(dataset.entries()) - 1, 1)
    assert _state(root) == _state(labelled)  # the same bytes as a labelling never stopped


def test_an_old_dataset_reads_unchanged_and_refuses_camera_training(small_dataset: Path) -> None:
    dataset = Dataset.open(small_dataset)
    assert all(dataset.read_run(e, images=False).camera is None for e in dataset.entries())
    default, lidar = (view_arrays(dataset, "val", None, bins_target, **kw)
                      for kw in ({}, {"labels": "lidar"}))
    assert np.array_equal(default["target"], lidar["target"], equal_nan=True)
    with pytest.raises(ConfigError, match=f"{small_dataset} has no camera labels.*depthq label"):
        view_arrays(dataset, "train", None, bins_target, labels="camera")
    with pytest.raises(ConfigError, match="Coll-Q-Net learns only from labels"):
        TrainConfig(model="coll", data=str(small_dataset), labels="camera")
    with pytest.raises(ConfigError, match=r"train\.labels must be one of"):
        TrainConfig(model="depth", data=str(small_dataset), labels="sonar")


@pytest.mark.slow
def test_a_depth_q_net_trains_on_camera_labels_and_drives(labelled: Path, labeller: Path, tmp_path: Path
                                                          ) -> None:
    from depthq.policies.registry import make_policy
    from depthq.train.trainer import train

    dataset = Dataset.open(labelled)
    camera = view_arrays(dataset, "train", None, bins_target, labels="camera")
    lidar = view_arrays(dataset, "train", None, bins_target)
    assert not np.array_equal(camera["target"], lidar["target"])  # the targets are the camera's
    assert np.array_equal(camera["frame_id"], lidar["frame_id"])  # of the same samples
    out = train(TrainConfig(model="depth", data=str(labelled), labels="camera", **TOY_TRAINING),
                tmp_path / "camera", progress=False)
    record = read_config(out)
    assert record["train"]["labels"] == "camera" and record["head"]["form"] == "depth_first"
    model = load_labeller(labeller)  # the checkpoint names the labeller its targets came from
    assert record["dataset"]["labeller"] == {"name": model.record["name"], "fingerprint": model.fingerprint}
    policy = make_policy(str(out))
    assert policy.act({"image": np.zeros((308, 410, 3), np.uint8)}) in (-1.0, 0.0, 1.0)
    stored = json.loads((out / "config.json").read_text())
    del stored["train"]["labels"]  # a record written before the setting
    (out / "config.json").write_text(json.dumps(unchecked(stored)))
    assert read_config(out)["train"]["labels"] == "lidar"


@pytest.mark.slow  # the labeller's training and a labelling: fixtures of ~16 s
def test_dataset_stats_rates_the_labels_against_the_lidar(labelled: Path, small_dataset: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dataset", "stats", str(labelled)]) == 0
    out = capsys.readouterr().out
    assert "camera labels (perception" in out and "nearest bin" in out
    assert all(band in out for band in ("0–0.5 m", "0.5–1 m", "1–2 m")) and "per bin" in out
    assert main(["dataset", "stats", str(labelled), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)["camera_labels"]["splits"]
    assert set(report) == {"train", "val"} and len(report["val"]["per_bin"]) == 26
    assert report["val"]["nearest"]["median"] >= 0
    assert main(["dataset", "stats", str(small_dataset)]) == 0
    assert "camera labels" not in capsys.readouterr().out  # nothing to rate


@pytest.mark.slow  # the labeller's training and a labelling: fixtures of ~16 s
def test_bad_inputs_exit_2_and_write_nothing(small_hard_dataset: Path, small_dataset: Path, labeller: Path,
                                             tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    hard, paper = tmp_path / "hard", tmp_path / "paper"
    shutil.copytree(small_hard_dataset, hard, ignore=shutil.ignore_patterns("features"))
    shutil.copytree(small_dataset, paper, ignore=shutil.ignore_patterns("features"))
    before = {root: _state(root) for root in (hard, paper)}
    cases = [  # (argv, what the message names)
        (["label", str(hard), "--from", "camera", "--labeller", str(labeller)], "'hard' family too"),
        (["label", str(paper), "--from", "camera", "--labeller", str(paper)], f"--labeller {paper}"),
        (["label", str(tmp_path / "none"), "--from", "camera", "--labeller", str(labeller)], "none"),
        (["labeller", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "l")], "none"),
        (["train", "--model", "depth", "--data", str(paper), "--labels", "camera", "--out",
          str(tmp_path / "m")], "depthq label"),
    ]
    for argv, named in cases:
        assert main(argv) == 2, argv
        assert named in capsys.readouterr().err, argv
    for argv, named in (  # argparse: a choice its flag does not list
        (["label", str(paper), "--from", "lidar", "--labeller", str(labeller)], "'lidar'"),
        (["labeller", "--data", str(paper), "--out", str(tmp_path / "l"), "--trunk", "mobilenet_v1_025"],
         "'mobilenet_v1_025'"),
    ):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2 and named in capsys.readouterr().err, argv
    assert {root: _state(root) for root in (hard, paper)} == before
    assert not any((tmp_path / name).exists() for name in ("l", "m", "none"))


def test_labels_of_two_labellers_or_a_labelling_under_way_are_refused_by_training(
    small_dataset: Path, tmp_path: Path
) -> None:
    from depthq.data.camera_labels import CameraLabels
    from depthq.train.trainer import train

    root = tmp_path / "data"
    shutil.copytree(small_dataset, root, ignore=shutil.ignore_patterns("features"))
    dataset = Dataset.open(root)
    first, second = "1" * 64, "2" * 64  # two labellers' fingerprints, as a `label --replace` stopped half way
    for k, entry in enumerate(dataset.entries()):
        bins = dataset.read_run(entry, images=False).bins
        dataset.set_camera_labels(entry, CameraLabels(bins, "floor", first if k % 2 else second))
    config = TrainConfig(model="depth", data=str(root), labels="camera", **TOY_TRAINING)
    with pytest.raises(ConfigError, match="camera labels of 2 labellers") as refused:
        train(config, tmp_path / "model", progress=False)
    assert first[:16] in str(refused.value) and second[:16] in str(refused.value)
    assert "--replace" in str(refused.value) and not (tmp_path / "model").exists()
    assert Dataset.open(small_dataset).labeller() is None  # a dataset without camera labels: none

    # `depthq label` rewriting the runs: a training is refused as that, not as a corrupted file
    entry = dataset.entries()[0]
    with dataset.reader(entry) as reader:  # the file rewritten, the manifest not yet
        write_labelled(dataset.path(entry), reader, CameraLabels(reader.run(False).bins, "floor", first))
    code = (f"from depthq.lock import exclusive\nwith exclusive({str(root)!r}, 'DIR', 'label'):\n"
            "    print('held', flush=True)\n    import time; time.sleep(60)\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")}
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        for attempt in (lambda: train(config, tmp_path / "model", progress=False),
                        lambda: Dataset.open(root).reader(entry)):
            with pytest.raises(ConfigError, match=rf"being labelled: `depthq label` \(PID {holder.pid}\)"):
                attempt()
    finally:
        holder.kill()
        holder.wait()
    with pytest.raises(DataError, match="corrupted"):  # no labelling under way: the file is what is wrong
        Dataset.open(root).reader(entry)
