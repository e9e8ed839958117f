"""A network's Q-net: its head built from a `HeadConfig` by the network `kind` names, or the whole
net read back from a checkpoint folder (`depthq.blocks.checkpoint` reads the folder; this builds it)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from depthq.blocks.checkpoint import load_trainable_state, read_checkpoint
from depthq.blocks.heads import Head, HeadConfig, QNet
from depthq.blocks.trunk import build_trunk
from depthq.configio import from_dict
from depthq.networks.registry import get_network


def build_head(config: HeadConfig) -> Head:
    """The head of the network `config.kind` names, checked by its rules (`Network.check_head`)."""
    network = get_network(config.kind)
    network.check_head(config)
    return network.build_head(config)


def load_qnet(
    folder: Path, weights: str | None = None, model: str | None = None, trunk: str | None = None
) -> tuple[QNet, dict[str, Any]]:
    """The trained network in `folder` in eval mode, and its config.json (`read_config`).

    `weights` (`weights_stem`): None takes the checkpoint's own choice (`TrainConfig.weights`).
    `model` / `trunk`, when given, must be what the folder holds. A missing, incomplete or corrupted
    folder, or one that does not match → an error naming the file.
    """
    record, tensors, path = read_checkpoint(Path(folder), weights, model, trunk)
    trunk_net = build_trunk(str(record.get("trunk")), tune_stages=record["train"].get("tune_stages", 0))
    net = QNet(trunk_net, build_head(from_dict(HeadConfig, record["head"])))
    load_trainable_state(net, tensors, path)
    return net.eval(), record
