"""The networks by name: `register_network` adds one (a class decorator, as LeRobot's policies
register their configs), `get_network` finds it, `network_names` lists them in the order registered.

A network registered in a process exists in that process only. Evaluation drives in worker processes
(`depthq.parallel`: even `workers=1` is a process of its own, started from depthq's own modules; a Ray
cluster's are other machines' processes), which rebuild a checkpoint's network by the name it records,
so a network of one's own must be found there too: declare it in its package's metadata as an entry
point of the group `depthq.networks` (pyproject.toml: `[project.entry-points."depthq.networks"]`,
`clearance = "mypackage.clearance:ClearanceNet"`); `network_names` and `get_network` of an unknown
name register the installed entry points' networks first. One registered by hand (a test, a notebook)
trains, exports and drives in its own process (`depthq.evaluate.online.drive`).
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import TypeVar

from depthq.errors import ConfigError
from depthq.networks.network import Network, NoSettings

N = TypeVar("N", bound=type[Network])
ENTRY_POINTS = "depthq.networks"  # the entry-point group of installed packages' networks

_NETWORKS: dict[str, Network] = {}
_installed = False  # whether the installed entry points' networks are registered


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
    if isinstance(name, str) and name not in _NETWORKS:
        _register_installed()
    try:
        return _NETWORKS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown network {name!r}; one of {network_names()}") from None


def network_names() -> tuple[str, ...]:
    """The registered networks' names, in the order registered (Depth-Q-Net, Coll-Q-Net first)."""
    _register_installed()
    return tuple(_NETWORKS)


def acting_classes() -> dict[str, type]:
    """The acting settings' classes (`Network.Acting`) of the registered networks that have some, by
    name (`EvalConfig.acting`'s)."""
    return {name: network.Acting for name in network_names()
            if (network := _NETWORKS[name]).Acting is not NoSettings}


def _register_installed() -> None:
    """Register the networks installed packages declare (`ENTRY_POINTS`), once per process."""
    global _installed
    if _installed:
        return
    _installed = True
    for point in entry_points(group=ENTRY_POINTS):
        if point.name not in _NETWORKS:
            try:
                cls = point.load()  # a module that registers its network on import has done so here
            except Exception as err:  # any error of a package's own module: name the entry point
                raise ConfigError(f"network {point.name!r} ({point.value}, an entry point of "
                                  f"{ENTRY_POINTS}) does not load: {err}") from err
            if point.name not in _NETWORKS:
                register_network(cls)
