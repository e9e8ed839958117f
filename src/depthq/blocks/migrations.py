"""Old on-disk shapes read as today's, in one place: one function per version of a checkpoint's
config.json (`depthq.checkpoint.format`), and the old names of the settings renamed or moved since
sweeps named model folders after them (docs/formats.md).

    checkpoint_v1   version 1 → 2: weight files gained their SHA-256 (in their own metadata); the
                    config is unchanged
    checkpoint_v2   version 2 → 3: config.json describes its policy and its dataset
    checkpoint_v3   version 3 as written before its later fields (0.1.0 is unreleased, so they came
                    without a version): fields added, renamed and moved read as today's, Depth-Q-Net's
                    own settings under its name (`own_settings`)
    sweep_setup     a sweep folder's reproduce.json written before sweeps ("preset") or before a
                    setting was part of a sweep's setup (`family`)
    summary_config  an evaluation's config (summary.json) written before networks owned their acting
                    settings: Depth-Q-Net's under its name
    RENAMED_SETTINGS, FOLDER_KEYS, RENAMED_EVAL_SETTINGS
                    settings by the names they had: their old flags (--select, --horizon, --rule), sweep
                    settings (--set select=final) and the model folders named after them
                    (depth_n200_s0_selectfinal) still take them

A dataset manifest's own migration is `depthq.data.manifest.upgrade_config`.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

from depthq.control.action_selection import ACTIONS
from depthq.data.manifest import Dataset, upgrade_config
from depthq.errors import ConfigError, DataError
from depthq.sim.canyon import PAPER

# The selection rule a record before version 3 acted by, by its head's kind: the two networks there were.
_LEGACY_RULES = {"depth": "farthest_nearest_bin", "coll": "lowest_collision_probability"}

# What every checkpoint before version 3 was made for: the simulated camera's 308 × 410 frames, and
# its dataset's rate, or 4 Hz (the default rate then) when its manifest is not found.
_LEGACY_FRAME_SIZE = (308, 410)
_LEGACY_DECISION_HZ = 4.0
# TrainConfig fields added within version 3, as a record written before them reads: the one behaviour
# there was (its feature unprojected, trained in float32 on LiDAR bins; no weight average), so such a
# folder still loads and resumes.
_ADDED_TRAIN = {"feature_projection": 0, "precision": "fp32", "labels": "lidar", "average": 0.0}
# Depth-Q-Net's own settings (`depthq.networks.depth_q_net.DepthSettings`), which a train record held
# among the others until #56 gave each network its own, under its name; the ones added within version 3
# as a record written before them reads (a one-step Depth-Q-Net; the paper's head, the default until
# "depth_first" was, and recorded only when it was not).
_DEPTH = "depth"
_DEPTH_SETTINGS = ("depth_loss", "lookahead", "lookahead_discount", "head_form", "output_bias",
                   "bin_gradient", "bootstrap")
_ADDED_DEPTH = {"lookahead": 1, "lookahead_discount": 1.0, "head_form": "concat"}
# HeadConfig fields a checkpoint's "head" can lack, as such a record reads: it was written before the
# field (action_scale, lookahead, feature_projection, form, output_bias, bin_gradient, in that order) or,
# for `form`, at "concat", which records left out until HeadConfig's defaults moved to TrainConfig (#33).
# These are the defaults HeadConfig had then, or the one behaviour there was: the paper's head, the action
# unscaled, the output bias 0, the bins' ReLU passing its own gradient back. Every
# record holds kind, feature_dim, hidden, n_bins and dropout (written by dataclasses.asdict from the
# first checkpoint on).
_ADDED_HEAD = {"action_scale": 1.0, "lookahead": 1, "feature_projection": 0, "form": "concat",
               "output_bias": 0.0, "bin_gradient": "relu"}
# Fields renamed within version 3 (old name → new), as a record written before the rename reads.
_RENAMED = {"train": {"select": "weights"}, "policy": {"selection": "rule"}}
# TrainConfig's sample settings, which it held itself until #33 moved them into `samples`
# (`depthq.data.samples.SampleConfig`).
_SAMPLE_SETTINGS = ("horizon", "min_frames", "every_run_end", "action_clip", "action_lag")

# TrainConfig settings by their old names (old → today's path): `select` became `weights` (#33), the
# sample settings moved into `samples`, Depth-Q-Net's own into `depth` (#56).
RENAMED_SETTINGS = {"select": "weights", **{name: f"samples.{name}" for name in _SAMPLE_SETTINGS},
                    **{name: f"{_DEPTH}.{name}" for name in _DEPTH_SETTINGS}}
# Today's path → the name model folders keep (`depthq.pipeline.layout.model_name`), so a sweep finds
# and reuses the folders trained before (`--set weights=final` is depth_n200_s0_selectfinal, as
# `--set select=final` was; `--set samples.horizon=2` is coll_n200_s0_horizon2; `--set
# depth.lookahead=3` is depth_n200_s0_lookahead3).
FOLDER_KEYS = {new: old for old, new in RENAMED_SETTINGS.items()}
# Depth-Q-Net's acting settings (`depthq.networks.depth_q_net.Selection`), which an evaluation's config
# held among the others until #56 gave each network its own, under its name (`EvalConfig.acting`); by
# their old names (old → today's path) as `depthq evaluate` and `depthq drive` still take them.
_DEPTH_ACTING = ("rule", "discount", "switch")
RENAMED_EVAL_SETTINGS = {name: f"{_DEPTH}.{name}" for name in _DEPTH_ACTING}
# What a sweep folder written before a setting was part of a sweep's setup holds for it.
_SETUP_ADDED = {"family": PAPER}
# A setup setting a sweep folder recorded as none, "the trainer's default", before presets named it
# (#56): that default, the one value it had (`TrainConfig.epochs`, 40 since sweeps were made).
_SETUP_UNSET = {"epochs": 40}


def migrate_checkpoint(record: dict[str, Any], version: int) -> dict[str, Any]:
    """A checkpoint's config.json of format `version` (1 to 3) in today's shape: each version's
    migration from `version` on."""
    if version < 2:
        record = checkpoint_v1(record)
    if version < 3:
        record = checkpoint_v2(record)
    return checkpoint_v3(record)


def checkpoint_v1(record: dict[str, Any]) -> dict[str, Any]:
    """Version 1 → 2: only the weight files changed (they record their SHA-256; a file without one
    loads with a warning, `depthq.checkpoint.read_weights`)."""
    return {**record, "format_version": 2}


def checkpoint_v2(record: dict[str, Any]) -> dict[str, Any]:
    """Version 2 → 3: the policy it was trained for and its dataset, as that dataset's manifest says
    (when it is found where the record points, relative paths from here), its default weights the
    best (`train.weights`) and no snapshots."""
    train = {"weights": "best", "snapshots": [], **record.get("train", {})}
    data = Path(str(train.get("data")))
    try:
        env = Dataset.open(data).config.get("env")
    except (ConfigError, DataError):
        warnings.warn(f"{data}: dataset not found; its decision rate is taken as {_LEGACY_DECISION_HZ:g} "
                      "Hz (a checkpoint written by an older depthq records none)", stacklevel=4)
        env = None
    world = (env or {}).get("world", {})
    camera = {"height": _LEGACY_FRAME_SIZE[0], "width": _LEGACY_FRAME_SIZE[1], **world.get("camera", {})}
    kind = (record.get("head") or {}).get("kind")
    old = {k: v for k, v in record.items() if k != "data_fingerprint"}
    return {
        **old,
        "format_version": 3,
        "train": train,
        "dataset": {"path": str(data), "fingerprint": record.get("data_fingerprint"), "env": env},
        "policy": {
            "decision_hz": float(world.get("decision_hz", _LEGACY_DECISION_HZ)),
            "frame_size": [camera["height"], camera["width"]],
            "actions": list(ACTIONS),
            "rule": _LEGACY_RULES.get(kind, ""),
            "bins": (env or {}).get("bins"),
        },
    }


def checkpoint_v3(record: dict[str, Any]) -> dict[str, Any]:
    """Version 3 as written today: fields renamed (`_RENAMED`) under their new names, the dataset's
    world before looks naming its look (`upgrade_config`), the head's and the training's fields added
    since at what they meant before (`_ADDED_HEAD`, `_ADDED_TRAIN`), the sample settings a train record
    held itself inside `train.samples`, a network's own settings under its name (`own_settings`). A
    record written today is returned as it is."""
    out = dict(record)
    for block, names in _RENAMED.items():
        if isinstance(out.get(block), dict):
            out[block] = {names.get(k, k): v for k, v in out[block].items()}
    dataset = out.get("dataset")
    if isinstance(dataset, dict) and isinstance(dataset.get("env"), dict):  # `appearance` → `look`
        out["dataset"] = {**dataset, "env": upgrade_config(dataset)["env"]}
    if isinstance(out.get("head"), dict):
        out["head"] = {**_ADDED_HEAD, **out["head"]}
    train = {**_ADDED_TRAIN, **out.get("train", {})}
    moved = {name: train.pop(name) for name in _SAMPLE_SETTINGS if name in train}
    if moved:
        train["samples"] = {**moved, **train.get("samples", {})}
    return {**out, "train": own_settings(train)}


def own_settings(train: dict[str, Any]) -> dict[str, Any]:
    """A train record with its network's own settings under the network's name (#56), as TrainConfig
    stores them (`TrainConfig.settings`): one written before held Depth-Q-Net's among the others
    (`_DEPTH_SETTINGS`, those added since at `_ADDED_DEPTH`), and so did every Coll-Q-Net's, at values
    that meant nothing to it (dropped). A record that holds its network's block is returned as it is."""
    model = train.get("model")
    if not isinstance(model, str) or model in train:
        return train
    flat = {name: train[name] for name in _DEPTH_SETTINGS if name in train}
    out = {k: v for k, v in train.items() if k not in _DEPTH_SETTINGS}
    if model == _DEPTH:
        out[_DEPTH] = {**_ADDED_DEPTH, **flat}
    return out


def sweep_setup(record: dict[str, Any]) -> dict[str, Any]:
    """The sweep a folder's reproduce.json records (`depthq.pipeline.sweep.Sweep.record`) in today's
    shape: under "sweep", or "preset" in a folder written before sweeps; a setup setting it predates
    (`_SETUP_ADDED`) or recorded as none (`_SETUP_UNSET`) at the one value there was."""
    setup = {**_SETUP_ADDED, **record.get("sweep", record.get("preset", {}))}
    return {**setup, **{k: v for k, v in _SETUP_UNSET.items() if setup.get(k) is None}}


def summary_config(config: dict[str, Any]) -> dict[str, Any]:
    """An evaluation's config, as its summary.json records it (`depthq.evaluate.online.EvalConfig`), in
    today's shape: one written before #56 held Depth-Q-Net's acting settings among the others
    (`_DEPTH_ACTING`), now under its name. A config written today is returned as it is."""
    flat = {name: config[name] for name in _DEPTH_ACTING if name in config}
    if not flat:
        return config
    out = {k: v for k, v in config.items() if k not in _DEPTH_ACTING}
    return {**out, _DEPTH: {**flat, **out.get(_DEPTH, {})}}
