"""Table I's offline columns: a checkpoint's loss on every validation sample of its dataset —
the training loss: absolute difference on the near bins (Depth-Q-Net) or binary cross-entropy (Coll-Q-Net)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from depthq.configio import from_dict
from depthq.data.manifest import Dataset
from depthq.data.views import view_arrays
from depthq.nets.checkpoint import load_qnet
from depthq.nets.trunk import preprocess
from depthq.train.config import TrainConfig
from depthq.train.features import load_features
from depthq.train.trainer import loss_function

METRICS = {"depth": "abs_diff", "coll": "cross_entropy"}


@torch.inference_mode()
def offline_metric(checkpoint: Path, which: str = "best") -> dict[str, Any]:
    """The metric over the validation split of the dataset the checkpoint was trained on."""
    net, config = load_qnet(Path(checkpoint), which=which)
    train = config["train"]
    kind = train["model"]
    dataset = Dataset.open(Path(train["data"]))
    train_config = from_dict(TrainConfig, train)
    arrays = view_arrays(dataset, "val", None, kind=kind, config=train_config.labels())
    actions = torch.from_numpy(np.asarray(arrays["action"], np.float32))
    targets = torch.from_numpy(np.asarray(arrays["target"], np.float32))
    size = int(train["input_size"])
    if net.trunk.frozen:
        features = load_features(dataset, train["trunk"], size, progress=False).gather("val", arrays).float()
    else:  # the trunk was trained with the head: run it on the frames themselves
        features = torch.cat([net.trunk(preprocess(frames, size)) for frames in _frames(dataset, arrays)])
    outputs = net.head(features, actions)
    loss, _ = loss_function(train_config)(outputs, targets)
    return {"metric": METRICS[kind], "value": float(loss), "samples": len(targets), "weights": which}


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
