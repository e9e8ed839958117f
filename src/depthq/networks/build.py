"""A network's Q-net: its head built from a `HeadConfig` by the network `kind` names, on its trunk (a
fresh one for training; `depthq.checkpoint.load_qnet` puts a checkpoint's weights into one)."""

from __future__ import annotations

from depthq.blocks.heads import Head, HeadConfig, QNet
from depthq.blocks.trunk import build_trunk
from depthq.networks.registry import get_network


def build_head(config: HeadConfig) -> Head:
    """The head of the network `config.kind` names, checked by its rules (`Network.check_head`)."""
    network = get_network(config.kind)
    network.check_head(config)
    return network.build_head(config)


def build_qnet(head: HeadConfig, trunk: str, tune_stages: int = 0) -> QNet:
    """The Q-net of `head` on the trunk `trunk` names (pretrained if it has weights; `tune_stages`: its
    late stages trained), the head fresh (its feature projection, if any, not fitted yet)."""
    return QNet(build_trunk(trunk, tune_stages=tune_stages), build_head(head))
