"""The networks: each a `Network` registered by name, owning what differs
between networks (its training, metric, rule, export and drawing), so that every layer above asks the
registry (`get_network`) instead of testing a network's name. Importing this package registers
Depth-Q-Net ("depth") and Coll-Q-Net ("coll"); a user's network registers with `register_network` (or
an entry point: `depthq.networks.registry`), its own settings a dataclass of its own (`Network.Settings`;
for acting, `Network.Acting`)."""

# isort: off
# Registered in this order, the paper's, which `network_names` (a sweep's default networks) keeps.
from depthq.networks.depth_q_net import DepthQNet, DepthSettings, Selection
from depthq.networks.coll_q_net import CollQNet

# isort: on
from depthq.networks.build import build_head, build_qnet
from depthq.networks.network import Network, NoSettings, Training, ValuePlot
from depthq.networks.registry import acting_classes, get_network, network_names, register_network

__all__ = ["CollQNet", "DepthQNet", "DepthSettings", "Network", "NoSettings", "Selection", "Training",
           "ValuePlot", "acting_classes", "build_head", "build_qnet", "get_network", "network_names",
           "register_network"]
