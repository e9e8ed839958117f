"""Dead outputs (docs/design.md#dead-outputs): the outputs of a Depth-Q-Net that are 0 for every frame
and every candidate action. The policy reads a bin at 0 as no reading (`depthq.control.action_selection`),
so a dead output is a direction it never sees, whatever the frame. Counted on a checkpoint's own
validation frames through the feature cache, in seconds; `depthq probe --parts dead` and the offline
columns of `depthq evaluate` (and so the reproduction report) say how many a checkpoint has.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from depthq.blocks.heads import QNet
from depthq.checkpoint import dataset_record, load_qnet, policy_record, read_config
from depthq.control.action_selection import candidate_sequences
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError
from depthq.networks import get_network
from depthq.train.features import load_activations, load_features

CHUNK_FRAMES = 256  # frames per head call: their candidates' hidden activations stay ≈ 13 MB at width 4096


@dataclass(frozen=True)
class DeadOutputs:
    """What `count_dead_outputs` found: the dead outputs' indices (a lookahead-K net's: step · n_bins +
    bin), out of how many, on how many frames of which split, each with how many candidates."""

    dead: tuple[int, ...]
    outputs: int
    frames: int
    split: str
    candidates: int

    def __str__(self) -> str:
        which = f" ({', '.join(map(str, self.dead))})" if self.dead else ""
        return (f"{len(self.dead)} of {self.outputs} outputs dead{which} on {self.frames} {self.split} "
                f"frames × {self.candidates} candidate actions")


def dead_outputs(values: np.ndarray) -> tuple[int, ...]:
    """The outputs of (frames, candidates, …) values that are 0 or below in every frame and for every
    candidate, as indices into the trailing dimensions flattened."""
    if values.ndim < 3:
        raise ConfigError(f"dead_outputs: expected (frames, candidates, outputs…) values, got {values.shape}")
    flat = values.reshape(values.shape[0] * values.shape[1], -1)
    return tuple(np.flatnonzero((flat <= 0).all(axis=0)).tolist())


def has_bins(net: QNet) -> bool:
    """Whether a net's outputs are depth bins behind a ReLU (a Depth-Q-Net's), the outputs that can die
    (its network's `outputs_bins`)."""
    return get_network(net.head.config.kind).outputs_bins


def candidates_of(net: QNet, actions: tuple[float, ...]) -> torch.Tensor:
    """The candidates a policy of `net` scores: the actions, or a lookahead net's held sequences."""
    k = net.head.config.lookahead
    held = np.asarray(actions, np.float64) if k == 1 else candidate_sequences(actions, k)
    return torch.tensor(held, dtype=torch.float32)


@torch.inference_mode()
def dead_in(net: QNet, features: torch.Tensor, candidates: torch.Tensor) -> tuple[int, ...]:
    """`dead_outputs` of a net's (eval mode) outputs on features (F, D) for every candidate, a chunk of
    frames at a time: an output alive in any chunk is alive."""
    alive = None
    for chunk in features.split(CHUNK_FRAMES):
        values = net.candidate_outputs(chunk.float(), candidates)
        above = (values.reshape(-1, values[0, 0].numel()) > 0).any(dim=0)
        alive = above if alive is None else alive | above
    if alive is None:
        raise ConfigError("dead outputs: no frames to look at")
    return tuple(torch.nonzero(~alive).flatten().tolist())


def split_features(folder: Path, split: str = "val", frames: int | None = None) -> torch.Tensor:
    """The cached inputs of the checkpoint's trainable part for the first `frames` (None: all) frames of
    `split` of its dataset (computed first if missing): the frozen trunk's features, or, of a trunk
    tuned from cached activations (`train.tune_stages`), those activations (`net_features` then runs
    its late stages)."""
    config = read_config(Path(folder))
    dataset = Dataset.open(Path(dataset_record(config).path))
    train = config["train"]
    size, tune = int(train["input_size"]), int(train.get("tune_stages", 0))
    table = (load_activations(dataset, tune, size, progress=False) if tune
             else load_features(dataset, train["trunk"], size, progress=False))
    spans = [table.runs[name] for name in sorted(table.runs) if name.startswith(f"{split}_")]
    if not spans:
        raise ConfigError(f"{folder}: its dataset {dataset.root} has no {split} runs to look at")
    rows = np.concatenate([np.arange(first, first + n) for first, n in spans])[:frames]
    return torch.from_numpy(np.asarray(table.features[rows], dtype=np.float32))


@torch.inference_mode()
def net_features(net: QNet, cached: torch.Tensor) -> torch.Tensor:
    """The features `net` sees for `split_features`' rows: a tuned trunk's late stages run on the cached
    activations; else the cached features themselves."""
    trunk = net.trunk
    return cached if trunk.trained_part() is None else trunk.late_features(cached)


def count_dead_outputs(
    folder: Path, weights: str | None = None, split: str = "val", frames: int | None = None
) -> DeadOutputs | None:
    """The dead outputs of the checkpoint in `folder` (`weights`: None its own choice) on the first
    `frames` (None: all) frames of its dataset's `split`, for every candidate action its policy
    scores; None for a net without depth bins (Coll-Q-Net)."""
    net, record = load_qnet(Path(folder), weights=weights)
    if not has_bins(net):
        return None
    features = net_features(net, split_features(folder, split, frames))
    candidates = candidates_of(net, policy_record(record).actions)
    outputs = net.head.config.n_bins * net.head.config.lookahead
    return DeadOutputs(dead_in(net, features, candidates), outputs, len(features), split, len(candidates))
