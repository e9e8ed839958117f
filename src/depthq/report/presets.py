"""Reproduction presets: the same pipeline at three sizes."""

from __future__ import annotations

from dataclasses import dataclass, replace

from depthq.data.subsets import PAPER_SUBSETS
from depthq.errors import ConfigError
from depthq.sim.world import DEFAULT_DECISION_HZ, NOMINAL_DECISION_HZ


@dataclass(frozen=True)
class Preset:
    """What `depthq reproduce` collects, trains and evaluates."""

    name: str
    runs: int  # usable training runs collected (the largest subset)
    val_runs: int
    max_steps: int  # collection step limit per run
    subsets: tuple[int, ...]  # nested training-set sizes (first n runs)
    seeds: tuple[int, ...]  # training seeds per (model, size)
    epochs: int | None  # None: the trainer's default budget
    train_batches: int
    val_batches: int
    canyons: str  # evaluation canyon set
    time_limit_s: float
    workers: int = 2
    decision_hz: float = DEFAULT_DECISION_HZ  # collection and evaluation: one decision per camera frame

    def __post_init__(self) -> None:
        if not self.subsets or max(self.subsets) > self.runs:
            raise ConfigError(f"preset {self.name}: subsets {self.subsets} must fit in {self.runs} runs")
        if not self.seeds:
            raise ConfigError(f"preset {self.name}: needs at least one seed")


PRESETS: dict[str, Preset] = {
    # A few minutes end to end; the test suite runs it.
    "smoke": Preset(
        "smoke",
        runs=6,
        val_runs=2,
        max_steps=60,
        subsets=(3, 6),
        seeds=(0,),
        epochs=2,
        train_batches=5,
        val_batches=2,
        canyons="eval:0-1",
        time_limit_s=5.0,
    ),
    # Same pipeline, fewer sizes and seeds: under 45 minutes on 2 CPU cores.
    "quick": Preset(
        "quick",
        runs=200,
        val_runs=20,
        max_steps=600,
        subsets=(50, 200),
        seeds=(0, 1),
        epochs=None,
        train_batches=100,
        val_batches=10,
        canyons="eval",
        time_limit_s=45.0,
    ),
    # The paper's Table I: 6 dataset sizes × 3 seeds × 2 networks, 20 canyons each.
    "paper": Preset(
        "paper",
        runs=900,
        val_runs=90,
        max_steps=600,
        subsets=PAPER_SUBSETS,
        seeds=(0, 1, 2),
        epochs=None,
        train_batches=100,
        val_batches=10,
        canyons="eval",
        time_limit_s=45.0,
    ),
}
# The paper's table at the camera's nominal 10 Hz, to compare with the calibrated rate (README).
PRESETS["nominal"] = replace(PRESETS["paper"], name="nominal", decision_hz=NOMINAL_DECISION_HZ)


def get_preset(name: str) -> Preset:
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; expected one of {sorted(PRESETS)}")
    return PRESETS[name]
