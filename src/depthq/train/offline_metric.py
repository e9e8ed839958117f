"""Table I's offline columns: a checkpoint's loss on every validation sample of its dataset —
the training loss: absolute difference on the near bins (Depth-Q-Net) or binary cross-entropy (Coll-Q-Net).
Training's validation re-run on the whole split, so it lives beside the trainer whose loss it takes;
`depthq.evaluate` reports it with the online metrics.

A Depth-Q-Net's dead outputs (`depthq.train.dead_outputs`: 0 for every validation frame and candidate
action) come with it: `dead_outputs` (their indices) of `outputs`.

A Depth-Q-Net that looks K steps ahead (docs/design.md#lookahead) is measured on its first step,
t+1, with the one-step loss: the quantity a one-step net's column holds, so a sweep over lookaheads
compares like with like; `steps` adds each step's, over the samples where that step is valid.

The dataset is the one the checkpoint records: where it was (an absolute path), or a folder given
instead, which must hold the same runs (its fingerprint). A checkpoint travels without its data:
when the dataset is not found, the metric is skipped with one line saying so.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

from depthq.blocks.trunk import preprocess
from depthq.checkpoint import chosen_weights, dataset_record, load_qnet, policy_record, weights_stem
from depthq.configio import from_dict
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError, DataError
from depthq.networks import get_network
from depthq.train.config import TrainConfig
from depthq.train.dead_outputs import candidates_of, dead_in, has_bins
from depthq.train.features import load_activations, load_features
from depthq.train.trainer import loss_function


@torch.inference_mode()
def offline_metric(checkpoint: Path, dataset: Dataset, weights: str | None = None) -> dict[str, Any]:
    """The metric over the validation split of `dataset`, the one the checkpoint was trained on
    (`training_data`)."""
    net, config = load_qnet(Path(checkpoint), weights=weights)
    train = config["train"]
    network = get_network(train["model"])
    train_config = from_dict(TrainConfig, train)
    lookahead = net.head.config.lookahead
    # scored against the LiDAR's bins whatever the training's labels: the measured depth is the truth
    arrays = network.samples(dataset, "val", None, train_config, labels="lidar")
    actions = torch.from_numpy(np.asarray(arrays["action"], np.float32))
    targets = torch.from_numpy(np.asarray(arrays["target"], np.float32))
    size = int(train["input_size"])
    if net.trunk.frozen:
        features = load_features(dataset, train["trunk"], size, progress=False).gather("val", arrays).float()
    elif train_config.tune_stages:  # its late stages on its frozen stages' cached activations
        table = load_activations(dataset, train_config.tune_stages, size, progress=False)
        features = net.trunk.late_features(table.gather("val", arrays).float())
    else:  # the trunk was trained with the head: run it on the frames themselves
        features = torch.cat([net.trunk(preprocess(frames, size)) for frames in _frames(dataset, arrays)])
    outputs = net.head(features, actions)
    stem = weights_stem(chosen_weights(config, weights, Path(checkpoint)))
    dead = {}
    if has_bins(net):
        candidates = candidates_of(net, policy_record(config).actions)
        dead = {"dead_outputs": list(dead_in(net, features, candidates)),
                "outputs": net.head.config.n_bins * lookahead}
    if lookahead == 1:
        loss, _ = loss_function(train_config)(outputs, targets)
        return {"metric": network.metric, "value": float(loss), "samples": len(targets), "weights": stem,
                **dead}
    one_step = network.step_loss(train_config.settings)
    valid = torch.from_numpy(arrays["mask"])
    steps = [float(one_step(outputs[valid[:, k], k], targets[valid[:, k], k])[0]) for k in range(lookahead)]
    return {"metric": network.metric, "value": steps[0], "samples": len(targets), "weights": stem,
            "steps": steps, **dead}


def training_data(record: dict[str, Any], data: Path | None) -> Dataset | None:
    """The dataset a checkpoint's config.json records: `data` (ConfigError if it holds other runs),
    else the recorded path if it still holds the same runs, else None and one line on stderr."""
    recorded = dataset_record(record)
    if data is not None:
        dataset = Dataset.open(Path(data))
        found = dataset.fingerprint()
        if recorded.fingerprint is not None and found != recorded.fingerprint:
            raise ConfigError(
                f"--data {data}: not the dataset this checkpoint was trained on (fingerprint "
                f"{found[:12]}…, the checkpoint records {recorded.fingerprint[:12]}… of {recorded.path})"
            )
        return dataset
    try:
        dataset = Dataset.open(Path(recorded.path))
    except (ConfigError, DataError) as err:
        why = f"its dataset is not found ({err})"
    else:
        if recorded.fingerprint is None or dataset.fingerprint() == recorded.fingerprint:
            return dataset
        why = f"{recorded.path} no longer holds the runs it was trained on"
    print(f"offline metrics skipped: {why}; pass --data DIR to compute them", file=sys.stderr)
    return None


def _frames(dataset: Dataset, arrays: dict[str, np.ndarray], batch: int = 64):
    """uint8 frames of the view's samples, in order, `batch` at a time."""
    readers = {}
    frames = []
    for run_id, frame_id in zip(arrays["run_id"].tolist(), arrays["frame_id"].tolist(), strict=True):
        if run_id not in readers:
            readers[run_id] = dataset.reader(dataset.entry("val", run_id))
        frames.append(readers[run_id].image(frame_id))
        if len(frames) == batch:
            yield np.stack(frames)
            frames = []
    if frames:
        yield np.stack(frames)
    for reader in readers.values():
        reader.close()
