"""A sweep: one dataset, then every (network, training runs, seed, variant) model trained and evaluated.

The presets (`depthq.pipeline.presets`) are sweeps; `depthq sweep` widens one: more seeds (`--seeds
0-9`), other sizes, one network, or a grid of training settings (`--set dropout=0,0.5`), each value
a *variant* whose models are named after it (`depth_n200_s0_dropout0.5`); a network's own setting
(`--set depth.lookahead=1,3`) is a variant of that network's models alone. A sweep's *setup* (the
dataset, the evaluation canyons, the training budget) is what its folder's results depend on; the
grid may change between runs of the same folder, so 10 seeds reuse the 3 a preset trained.
"""

from __future__ import annotations

import itertools
import json
import re
import typing
from dataclasses import dataclass, field, replace
from typing import Any

from depthq.blocks.migrations import RENAMED_SETTINGS
from depthq.data.recorder import CollectConfig
from depthq.errors import ConfigError
from depthq.evaluate.online import EvalConfig, parse_canyon_set
from depthq.flags import build_config, config_flags, get_path, parse_value
from depthq.networks import network_names
from depthq.pipeline.layout import model_name, setting_text
from depthq.sim.canyon import FAMILIES, eval_set, split_family
from depthq.sim.world import world_for
from depthq.train.config import TrainConfig

Variant = tuple[tuple[str, Any], ...]  # (TrainConfig field path, value) pairs; () is the preset's own setting
Settings = tuple[tuple[str, Any], ...]  # (field path, value) pairs: a partial config, the rest its defaults
# The grid's own axes, or fixed by the sweep's setup: not for --set.
NOT_IN_GRID = ("model", "data", "runs", "seed")
_SAFE = re.compile(r"^[A-Za-z0-9._+-]+$")  # a value that can be part of a folder name
_INT = re.compile(r"^-?[0-9]+$")


@dataclass(frozen=True)
class Model:
    """One cell of the grid: a network trained on the first `runs` runs with `seed`, in `variant`."""

    net: str
    runs: int
    seed: int
    variant: Variant = ()
    # The settings of `variant` that differ from the sweep's own: they name the model's folders, so a
    # variant equal to the preset (e.g. dropout=0.0) reuses the preset's models.
    differs: Variant = ()

    @property
    def name(self) -> str:
        return model_name(self.net, self.runs, self.seed, self.differs)

    @property
    def settings(self) -> Variant:
        """The settings of `variant` its network has (`own_settings`): `--set depth.lookahead=1,3,5`
        trains each Coll-Q-Net once (and every variant's row shows it)."""
        return own_settings(self.net, self.variant)


def own_settings(net: str, settings: Settings) -> Settings:
    """The settings (field paths) of `settings` that network `net` has: those of another network's own
    settings (`TrainConfig.settings`, 'depth.lookahead' of a Coll-Q-Net) left out."""
    others = set(network_names()) - {net}
    return tuple((k, v) for k, v in settings if k.partition(".")[0] not in others)


@dataclass(frozen=True)
class Sweep:
    """What `depthq sweep` (and `depthq reproduce`, for a preset) collects, trains and evaluates:
    partial configs of its three stages, and the grid of models."""

    name: str
    # The dataset: its usable training runs (the largest subset, at least), validation runs, step cap
    # per run and world, whose canyon family and decision rate are the sweep's (its evaluations'
    # rate too: one decision per camera frame).
    collect: CollectConfig
    subsets: tuple[int, ...]  # nested training-set sizes (first n runs)
    seeds: tuple[int, ...]  # training seeds per (network, size, variant)
    # What every model's training sets (TrainConfig field paths and values): a preset names every
    # field (`depthq.pipeline.presets.TRAINING`); a field left out is at its default.
    train: Settings
    canyons: str  # evaluation canyon set, as `depthq evaluate --canyons` takes it
    # What every evaluation sets besides its canyons and rate (EvalConfig field paths and values).
    evaluate: Settings = ()
    workers: int = 2
    # The networks trained; by default every registered one (a preset names its own).
    nets: tuple[str, ...] = field(default_factory=network_names)
    grid: tuple[tuple[str, tuple[Any, ...]], ...] = ()  # TrainConfig fields and the values to try

    def __post_init__(self) -> None:
        for what, settings, own in (("train", self.train, NOT_IN_GRID),
                                    ("evaluate", self.evaluate, ("canyons", "decision_hz"))):
            mine = sorted(set(dict(settings)) & set(own))
            if mine:
                raise ConfigError(f"sweep {self.name}: {what} settings {mine} are the sweep's own")
        self.eval_config()  # a clear error for a bad --canyons or evaluation setting, before any work
        runs = self.collect.runs
        if not self.subsets or min(self.subsets) < 1 or max(self.subsets) > runs:
            raise ConfigError(f"sweep {self.name}: sizes {self.subsets} must be in 1..{runs} "
                              f"(the training runs it collects, --runs)")
        if list(self.subsets) != sorted(self.subsets):  # the tables' rows: nested, smallest first
            raise ConfigError(f"sweep {self.name}: sizes {self.subsets} must be increasing, e.g. "
                              f"{','.join(map(str, sorted(set(self.subsets))))}")
        if not self.seeds or min(self.seeds) < 0:
            raise ConfigError(f"sweep {self.name}: needs seeds >= 0, got {self.seeds}")
        if not self.nets or set(self.nets) - set(network_names()):
            raise ConfigError(f"sweep {self.name}: networks must be some of {network_names()}, "
                              f"got {self.nets}")
        for values in (self.subsets, self.seeds, self.nets):
            if len(set(values)) != len(values):
                raise ConfigError(f"sweep {self.name}: {values} repeats a value")
        for model in self.models():  # every variant must be a valid training, before any work
            self.train_config(model, "data")

    @property
    def family(self) -> str:
        """The canyon family the dataset is collected in (`canyons` may name another)."""
        return self.collect.env.world.family

    @property
    def decision_hz(self) -> float:
        """Decisions (camera frames) per second, in collection and evaluation."""
        return self.collect.env.world.decision_hz

    @property
    def time_limit_s(self) -> float:
        """Seconds per evaluation run."""
        return self.eval_config().env.time_limit_s

    def eval_config(self) -> EvalConfig:
        """How every policy of the sweep is evaluated: in `canyons`, at the data's decision rate."""
        return build_config(EvalConfig, {"canyons": parse_canyon_set(self.canyons),
                                         "decision_hz": self.decision_hz, **dict(self.evaluate)})

    def variants(self) -> list[Variant]:
        keys = [k for k, _ in self.grid]
        grid = itertools.product(*(values for _, values in self.grid))
        return [tuple(zip(keys, values, strict=True)) for values in grid]

    def models(self) -> list[Model]:
        """Seed-major: an interrupted sweep already holds a whole table for its first seed."""
        # Each network's own settings: a default may differ between them (`TrainConfig.head_form`).
        differs = {(net, variant): differing(net, variant, self.train)
                   for variant in self.variants() for net in self.nets}
        return [
            Model(net, n, seed, variant, differs[net, variant])
            for seed in self.seeds
            for variant in self.variants()
            for n in self.subsets
            for net in self.nets
        ]

    def train_config(self, model: Model, data: str) -> TrainConfig:
        own = {"model": model.net, "data": data, "runs": model.runs, "seed": model.seed}
        shared = dict(own_settings(model.net, self.train))  # what every model trains with: its network's
        return build_config(TrainConfig, own | shared | dict(model.settings))

    def setup(self) -> dict[str, Any]:
        """What a folder's dataset, checkpoints and evaluations depend on (not the grid's extent), by
        the names folders have recorded it under since sweeps were made (the dataset's manifest
        refuses any other collection setting)."""
        budget = self.train_config(Model(self.nets[0], 1, 0), "data")  # the budget every model trains with
        return json.loads(json.dumps({
            "runs": self.collect.runs,
            "val_runs": self.collect.val_runs,
            "max_steps": self.collect.max_steps,
            "epochs": budget.epochs,
            "train_batches": budget.train_batches,
            "val_batches": budget.val_batches,
            "canyons": self.canyons,
            "time_limit_s": self.time_limit_s,
            "decision_hz": self.decision_hz,
            "family": self.family,
        }))

    def record(self) -> dict[str, Any]:
        """The sweep as its folder's reproduce.json and report record it: its setup and its grid."""
        grid = {"name": self.name, "subsets": self.subsets, "seeds": self.seeds, "workers": self.workers,
                "nets": self.nets, "grid": self.grid}
        return {**json.loads(json.dumps(grid)), **self.setup()}


def retarget(
    sweep: Sweep, family: str | None = None, canyons: str | None = None, decision_hz: float | None = None,
    look: str | None = None,
) -> Sweep:
    """`sweep` with its data collected in canyon `family`, evaluated in `canyons` (by default that
    family's eval canyons; e.g. 'hard/val:1000-1019' to choose on val canyons) at `decision_hz`, both
    in `look` (docs/design.md#looks; none: the family's own). Evaluation canyons of another family than
    the sweep's own bring their family's time limit."""
    changes: dict[str, Any] = {}
    world = sweep.collect.env.world
    if family is not None and family != sweep.family:
        if family not in FAMILIES:
            raise ConfigError(f"--family {family!r}: unknown canyon family; one of {sorted(FAMILIES)}")
        world = world_for(world, family)
        changes["canyons"] = eval_set(family)
    if canyons is not None:
        changes["canyons"] = canyons
    if "canyons" in changes:
        target = split_family(changes["canyons"])[0]
        if target != split_family(sweep.canyons)[0]:
            limit = FAMILIES[target].time_limit_s
            changes["evaluate"] = tuple({**dict(sweep.evaluate), "time_limit_s": limit}.items())
    if decision_hz is not None:
        world = replace(world, decision_hz=decision_hz)
    if look is not None:
        world = replace(world, look=look)
        evaluate = dict(changes.get("evaluate", sweep.evaluate))
        changes["evaluate"] = tuple({**evaluate, "look": look}.items())
    if world != sweep.collect.env.world:
        changes["collect"] = replace(sweep.collect, env=replace(sweep.collect.env, world=world))
    return replace(sweep, **changes)


def widened(sweep: Sweep, runs: int | None = None, **changes: Any) -> Sweep:
    """`sweep` collecting `runs` training runs (None: its own) with `changes` to its other fields
    (subsets, seeds, nets, grid, name): the sizes are checked against the runs together."""
    if runs is not None:
        changes["collect"] = replace(sweep.collect, runs=runs)
    return replace(sweep, **changes)


def variant_label(variant: Variant) -> str:
    return ", ".join(f"{k}={setting_text(v)}" for k, v in variant) or "preset"


def parse_ints(text: str, what: str) -> tuple[int, ...]:
    """'0-9', '0,2,5' or '0-2,7' → the integers, in order."""
    values: list[int] = []
    try:
        for part in text.split(","):
            low, _, high = part.partition("-")
            values += range(int(low), int(high or low) + 1)
    except ValueError:
        raise ConfigError(f"{what} must be integers or ranges such as 0-9 or 50,200; got {text!r}") from None
    if not values:
        raise ConfigError(f"{what} names no value: {text!r}")
    return tuple(values)


def differing(net: str, variant: Variant, train: Settings = ()) -> Variant:
    """The settings of `variant` that `net` has (`Model.settings`) and whose values differ from its own
    under a sweep's `train` settings: what names its models' folders (`Model.differs`)."""
    given = {"model": net, "data": "data", "runs": 1, "seed": 0} | dict(own_settings(net, train))
    own = build_config(TrainConfig, given)
    settings = Model(net, 1, 0, variant).settings
    return tuple((k, v) for k, v in settings if get_path(own, k) != v)


def parse_setting(text: str) -> tuple[str, tuple[Any, ...]]:
    """'dropout=0,0.5' → ('dropout', (0.0, 0.5)): a TrainConfig field (its path below a nested config:
    'samples.horizon=1,2') and the values to try, each parsed as `depthq train`'s flag parses it
    (`depthq.flags.parse_value`: 'lr=none' is `--lr none`). A tuple field takes each value as items
    joined by '+': 'snapshots=40,40+80' → ((40,), (40, 80))."""
    key, sep, raw = text.partition("=")
    key = key.strip().replace("-", "_")  # the flag's spelling (depthq train --action-scale) or the field's
    key = RENAMED_SETTINGS.get(key, key)
    flags = {f.path: f for f in config_flags(TrainConfig)}
    if not sep or not raw:
        raise ConfigError(f"--set takes FIELD=VALUE[,VALUE…], got {text!r}")
    if key not in flags or key in NOT_IN_GRID:
        allowed = sorted(set(flags) - set(NOT_IN_GRID))
        raise ConfigError(f"--set {key!r} is not a training setting one can sweep; one of {allowed}")
    values = []
    tupled = typing.get_origin(flags[key].hint) is tuple  # its items joined by '+' here, by ',' in a flag
    for item in raw.split(","):
        value = parse_value(flags[key], item.replace("+", ",") if tupled else item, f"--set {key}")
        # An int for a setting that may be unset stays an int, as folders were always named: `--set
        # average=0` is …_average0, not …_average0.0.
        unset_default = not isinstance(flags[key].default, float)
        if isinstance(value, float) and unset_default and _INT.match(item.strip()):
            value = int(item)
        if not _SAFE.match(setting_text(value)):
            raise ConfigError(f"--set {key}: value {item!r} cannot name a model folder")
        values.append(value)
    if len(set(map(str, values))) != len(values):
        raise ConfigError(f"--set {key}: {raw!r} repeats a value")
    return key, tuple(values)
