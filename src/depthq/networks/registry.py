"""The networks by name: `register_network` adds one (a class decorator, as LeRobot's policies
register their configs), `get_network` finds it, `network_names` lists them in the order registered.

A network registered outside `depthq.networks` (in a user's module, or a test) exists in the process
that registered it. Work done in other processes needs its module imported there too: evaluation with
`workers` > 1 (each worker process, `depthq.parallel`) and a sweep's stages rebuild the network by
name, so register it in a module those processes import (e.g. one the run's entry point imports
before `depthq.cli`), or evaluate with `workers=1`, in-process.
"""

from __future__ import annotations

from typing import TypeVar

from depthq.errors import ConfigError
from depthq.networks.network import Network

N = TypeVar("N", bound=type[Network])

_NETWORKS: dict[str, Network] = {}


def register_network(cls: N) -> N:
    """Register the network class `cls` under its `name` (an instance of it: networks hold no state)."""
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise ConfigError(f"a network's name must be a word (letters, digits, _), got {name!r}")
    if name in _NETWORKS and type(_NETWORKS[name]) is not cls:
        raise ConfigError(f"network {name!r} is registered already ({type(_NETWORKS[name]).__name__})")
    _NETWORKS[name] = cls()
    return cls


def get_network(name: str) -> Network:
    """The network registered as `name` (a ConfigError naming the registered ones if none is)."""
    try:
        return _NETWORKS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown network {name!r}; one of {network_names()}") from None


def network_names() -> tuple[str, ...]:
    """The registered networks' names, in the order registered (Depth-Q-Net, Coll-Q-Net first)."""
    return tuple(_NETWORKS)
