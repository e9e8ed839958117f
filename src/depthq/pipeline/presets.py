"""Reproduction presets: the same sweep at three sizes (the paper's also at the nominal rate), and
the hard canyon family's Table I (`hard`)."""

from __future__ import annotations

from dataclasses import replace

from depthq.data.recorder import CollectConfig
from depthq.data.subsets import PAPER_SUBSETS
from depthq.errors import ConfigError
from depthq.pipeline.sweep import Sweep, retarget
from depthq.sim.world import NOMINAL_DECISION_HZ

PRESETS: dict[str, Sweep] = {
    # Under a minute end to end (`depthq.pipeline.preset_times`); the test suite runs it.
    "smoke": Sweep(
        "smoke",
        collect=CollectConfig(runs=6, val_runs=2, max_steps=60),
        subsets=(3, 6),
        seeds=(0,),
        train=(("epochs", 2), ("train_batches", 5), ("val_batches", 2)),
        canyons="eval:0-1",
        evaluate=(("time_limit_s", 5.0),),
    ),
    # Same pipeline, fewer sizes and seeds.
    "quick": Sweep(
        "quick",
        collect=CollectConfig(runs=200, val_runs=20, max_steps=600),
        subsets=(50, 200),
        seeds=(0, 1),
        train=(("train_batches", 100), ("val_batches", 10)),
        canyons="eval",
        evaluate=(("time_limit_s", 45.0),),
    ),
    # The paper's Table I: 6 dataset sizes × 3 seeds × 2 networks, 20 canyons each.
    "paper": Sweep(
        "paper",
        collect=CollectConfig(runs=900, val_runs=90, max_steps=600),
        subsets=PAPER_SUBSETS,
        seeds=(0, 1, 2),
        train=(("train_batches", 100), ("val_batches", 10)),
        canyons="eval",
        evaluate=(("time_limit_s", 45.0),),
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
