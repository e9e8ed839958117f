"""Reproduction presets: the same sweep at three sizes (the paper's also at the nominal rate), and
the hard canyon family's Table I (`hard`).

A preset names everything it trains: its networks (a network registered later joins an ad-hoc
sweep, not a preset) and every training setting (`TRAINING`), so that neither a new network nor a
changed default changes the models `depthq reproduce` trains.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from depthq.data.recorder import CollectConfig
from depthq.data.subsets import PAPER_SUBSETS
from depthq.errors import ConfigError
from depthq.networks import CollQNet, DepthQNet
from depthq.pipeline.sweep import Sweep, retarget
from depthq.sim.world import NOMINAL_DECISION_HZ

NETS = (DepthQNet.name, CollQNet.name)  # the paper's two networks, in its tables' order
# Every TrainConfig field but a sweep's own (`NOT_IN_GRID`: model, data, runs, seed), by field path, and
# every setting of NETS' own (`depth.*`: a network trains with its own alone); tests/test_reproduce.py
# checks that none is left out. None is the network's own where a field's default depends on its
# network (`lr`, `average`, `weights`: `TrainConfig`; `depth.head_form`: `DepthSettings`).
TRAINING: dict[str, Any] = {
    "epochs": 40, "train_batches": 100, "val_batches": 10, "batch_size": 64, "lr": None, "rho": 0.95,
    "eps": 1e-08, "weight_decay": 4e-05, "trunk": "efficientnet_lite0_columns", "tune_stages": 0,
    "dropout": 0.0, "action_scale": 10.0, "input_size": 128, "depth.depth_loss": "original",
    "depth.lookahead": 1, "depth.lookahead_discount": 1.0, "feature_projection": 0, "hidden": 4096,
    "depth.head_form": None, "depth.output_bias": 0.0, "depth.bin_gradient": "relu", "depth.bootstrap": 0.0,
    "mirror": False, "labels": "lidar", "samples.horizon": 5, "samples.min_frames": 20,
    "samples.every_run_end": True, "samples.action_clip": 1.0, "samples.action_lag": 0, "weights": None,
    "snapshots": (), "average": None, "precision": "fp32",
}


def _training(**changes: Any) -> tuple[tuple[str, Any], ...]:
    """`TRAINING` with `changes` (a smaller budget), as a sweep's settings."""
    return tuple({**TRAINING, **changes}.items())


PRESETS: dict[str, Sweep] = {
    # Under a minute end to end (`depthq.pipeline.preset_times`); the test suite runs it.
    "smoke": Sweep(
        "smoke",
        collect=CollectConfig(runs=6, val_runs=2, max_steps=60),
        subsets=(3, 6),
        seeds=(0,),
        train=_training(epochs=2, train_batches=5, val_batches=2),
        canyons="eval:0-1",
        evaluate=(("time_limit_s", 5.0),),
        nets=NETS,
    ),
    # Same pipeline, fewer sizes and seeds.
    "quick": Sweep(
        "quick",
        collect=CollectConfig(runs=200, val_runs=20, max_steps=600),
        subsets=(50, 200),
        seeds=(0, 1),
        train=_training(),
        canyons="eval",
        evaluate=(("time_limit_s", 45.0),),
        nets=NETS,
    ),
    # The paper's Table I: 6 dataset sizes × 3 seeds × 2 networks, 20 canyons each.
    "paper": Sweep(
        "paper",
        collect=CollectConfig(runs=900, val_runs=90, max_steps=600),
        subsets=PAPER_SUBSETS,
        seeds=(0, 1, 2),
        train=_training(),
        canyons="eval",
        evaluate=(("time_limit_s", 45.0),),
        nets=NETS,
    ),
}
# The paper's table at the camera's nominal 10 Hz, to compare with the calibrated rate (docs/calibration.md).
PRESETS["nominal"] = replace(retarget(PRESETS["paper"], decision_hz=NOMINAL_DECISION_HZ), name="nominal")
# Table I in the hard canyon family (docs/hard_canyons.md): its own data, its 20 eval canyons, runs
# long enough to reach the canyon's end; success = the end reached without a collision.
_HARD = retarget(PRESETS["paper"], family="hard")
PRESETS["hard"] = replace(_HARD, name="hard", collect=replace(_HARD.collect, runs=500),
                          subsets=(50, 200, 500))


def get_preset(name: str) -> Sweep:
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; expected one of {sorted(PRESETS)}")
    return PRESETS[name]
