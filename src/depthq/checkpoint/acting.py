"""Which weights of a checkpoint act, and the network that acts: a checkpoint's own choice
(`TrainConfig.weights`) unless its weight average fails its check (docs/design.md#weight-average), the
weight file that choice names, and the network rebuilt from it. Training (`depthq train` reports it),
the policies and evaluation ask here, so the choice is made in one place."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from torch import Tensor

from depthq.blocks.heads import HeadConfig, QNet
from depthq.checkpoint.format import (
    CONFIG,
    load_trainable_state,
    read_config,
    read_sidecar,
    read_weights,
    weights_stem,
)
from depthq.configio import from_dict
from depthq.errors import ConfigError
from depthq.networks import build_qnet

# A weight average worse than the final weights on validation by more than this many standard errors
# is not acted with by default (`average_fails`): 1.1–3.6 for the six broken averages found on `val`
# (each drove less far than its final weights), at most 0.73 for the others but one (1.02, as far
# with either) (docs/research/weights_check.md#weights-check).
AVERAGE_TOLERANCE_SE = 1.0


def chosen_weights(record: dict[str, Any], weights: str | None, folder: Path | None = None) -> str:
    """`weights`, or when None the checkpoint's own choice (`TrainConfig.weights`), where the weight
    average fails its check (`average_fails`, given the checkpoint's `folder`) the final weights."""
    if weights is not None:
        return weights
    own = str(record["train"]["weights"])
    return "final" if own == "average" and folder is not None and average_fails(folder, record) else own


def average_margin(folder: Path, record: dict[str, Any]) -> float | None:
    """The weight average's validation loss (average.json) minus the final weights' (last.json), in
    standard errors of that difference (the per-sample spreads over the validation samples, taken as
    independent); None where either record, or its loss, is missing."""
    try:
        average, final = read_sidecar(folder, "average"), read_sidecar(folder, "last")
    except FileNotFoundError:
        return None
    keys = ("val_loss", "val_loss_std")
    samples = record["train"].get("val_batches", 0) * record["train"].get("batch_size", 0)
    if samples < 1 or not all(isinstance(r.get(k), (int, float)) for r in (average, final) for k in keys):
        return None
    error = ((average["val_loss_std"] ** 2 + final["val_loss_std"] ** 2) / samples) ** 0.5
    difference = average["val_loss"] - final["val_loss"]
    return difference / error if error > 0 else math.copysign(math.inf, difference) if difference else 0.0


def average_fails(folder: Path, record: dict[str, Any]) -> bool:
    """Whether the weight average is worse than the final weights on validation by more than
    `AVERAGE_TOLERANCE_SE` standard errors (`average_margin`): averaging an epoch in which an output
    unit was dead with epochs in which it lived leaves a phantom obstacle the loss shows
    (docs/research/weights_check.md#weights-check). False where the margin cannot be computed."""
    margin = average_margin(folder, record)
    return margin is not None and margin > AVERAGE_TOLERANCE_SE


def read_checkpoint(
    folder: Path, weights: str | None = None, model: str | None = None, trunk: str | None = None
) -> tuple[dict[str, Any], dict[str, Tensor], Path]:
    """A checkpoint folder's config.json (`read_config`), the tensors of its weights and their file;
    `load_qnet` builds the network from them.

    `weights` (`weights_stem`): None takes the checkpoint's own choice (`TrainConfig.weights`).
    `model` / `trunk`, when given, must be what the folder holds. A missing, incomplete or corrupted
    folder, or one that does not match → an error naming the file.
    """
    folder = Path(folder)
    if weights is not None:
        weights_stem(weights)  # a bad value fails before the folder is looked at
    if not folder.is_dir():
        raise ConfigError(f"{folder}: no such checkpoint folder")
    record = read_config(folder)
    head = record.get("head")
    kind = head.get("kind") if isinstance(head, dict) else None
    if not isinstance(kind, str) or not kind:
        raise ConfigError(f"{folder / CONFIG}: unknown model kind {kind!r}")
    for asked, held, what in ((model, kind, "model"), (trunk, record.get("trunk"), "trunk")):
        if asked is not None and asked != held:
            raise ConfigError(f"{folder} holds a {what} {held!r}, not the {asked!r} asked for")
    chosen = chosen_weights(record, weights, folder)
    path = folder / f"{weights_stem(chosen)}.safetensors"
    if not path.is_file():
        train = record["train"]
        if chosen.startswith("epoch:"):
            why = f"its snapshots are at epochs {train['snapshots']}"
        elif chosen == "average":
            why = ("its average's first epoch is not reached yet?" if train.get("average")
                   else "it was trained without train.average")
        else:
            why = "no epoch finished yet?"
        raise ConfigError(f"{folder}: no {path.name} for weights {chosen!r} ({why})")
    tensors, _ = read_weights(path)
    return record, tensors, path


def load_qnet(
    folder: Path, weights: str | None = None, model: str | None = None, trunk: str | None = None
) -> tuple[QNet, dict[str, Any]]:
    """The trained network in `folder` in eval mode, and its config.json (`read_config`); the
    arguments and errors as `read_checkpoint`'s."""
    record, tensors, path = read_checkpoint(Path(folder), weights, model, trunk)
    head = from_dict(HeadConfig, record["head"])
    net = build_qnet(head, str(record.get("trunk")), record["train"].get("tune_stages", 0))
    load_trainable_state(net, tensors, path)
    return net.eval(), record
