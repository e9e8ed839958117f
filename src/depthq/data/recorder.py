"""Data collection (docs/design.md#recorder): OU exploration runs in fresh canyons, written as a run dataset.

As in the original recorder: the OU command drives the robot unclipped (up to the TurtleBot3's
2.84 rad/s), the bump check runs from the first step, the first `skip_frames` frames of every run
are driven but not saved, and a run ends at a bump or after `env.time_limit_s` (50 s).

Run `i` of split `s` depends on (seed, s, i) alone: it drives canyon `s:i` (the `train` or `val`
canyon stream, disjoint from each other and from the evaluation canyons) with sensor noise and OU
noise seeded from `SeedSequence(seed, spawn_key=(split, i))`. So the stored arrays are the same
whatever the number of workers and however often the collection was interrupted and resumed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from depthq.configio import check_seed, to_dict
from depthq.control.ou import OUConfig, OUPolicy
from depthq.control.policy import Policy
from depthq.data import StorageConfig
from depthq.data.manifest import Dataset, run_path
from depthq.data.run import SPLITS, Run, RunMeta
from depthq.data.runfile import FileInfo, write_run
from depthq.data.samples import usable
from depthq.errors import ConfigError
from depthq.parallel import LOCAL, Executor
from depthq.progress import Bar
from depthq.sim.canyon import PAPER, CanyonId
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.look import look_images
from depthq.sim.world import DEFAULT_DECISION_HZ, TURTLEBOT3_MAX_YAW_RATE, WorldConfig, world_for

MAX_DURATION_S = 50.0  # the original's max_duration of a collection run
SKIP_FRAMES = 9  # the original did not save the first 9 frames of a run (skip_first=8)


def exploration_env(
    decision_hz: float = DEFAULT_DECISION_HZ, max_duration_s: float = MAX_DURATION_S, family: str = PAPER
) -> EnvConfig:
    """The collection env: the OU command is applied up to the robot's own limit, not clipped to ±1;
    the world of canyon `family` (its runs drive `family`'s train and val canyons, the manifest's
    env.world records which)."""
    world = WorldConfig(decision_hz=decision_hz, max_yaw_rate=TURTLEBOT3_MAX_YAW_RATE)
    return EnvConfig(world=world_for(world, family), time_limit_s=max_duration_s)


@dataclass(frozen=True)
class CollectConfig:
    """What a dataset is made of; stored in its manifest (a folder refuses a different one)."""

    runs: int = 900  # usable training runs (data.min_frames frames at least; shorter ones are kept too)
    val_runs: int = 90  # usable validation runs (in their own canyons)
    max_steps: int = 600  # a hard cap on steps per run ("step_limit"), beside env.time_limit_s
    skip_frames: int = SKIP_FRAMES  # the first frames of every run, driven but not stored
    env: EnvConfig = field(default_factory=exploration_env)  # the robot's commands unclipped, 50 s runs
    ou: OUConfig = field(default_factory=OUConfig)  # the exploration policy
    data: StorageConfig = field(default_factory=StorageConfig)  # what is stored; samples are training's
    # Which draw: run i of a split drives its canyon with sensor and OU noise seeded from (seed, split, i).
    # The manifest records it beside the rest of the config (`recorded`), as it always has.
    seed: int = 0

    def __post_init__(self) -> None:
        check_seed(self.seed)
        if self.runs < 1:
            raise ConfigError(f"--runs must be >= 1, got {self.runs}")
        if self.val_runs < 0:
            raise ConfigError(f"--val-runs must be >= 0, got {self.val_runs}")
        if self.max_steps < 1:
            raise ConfigError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.skip_frames < 0:
            raise ConfigError(f"skip_frames must be >= 0, got {self.skip_frames}")
        steps = min(self.max_steps, math.floor(self.env.time_limit_s / self.env.world.period + 1e-9))
        if steps + 1 - self.skip_frames < self.data.min_frames:
            raise ConfigError(
                f"runs of at most {steps} steps (max_steps {self.max_steps}, {self.env.time_limit_s} s "
                f"at {self.env.world.decision_hz:g} Hz) keep at most {steps + 1 - self.skip_frames} frames "
                f"after skipping {self.skip_frames}: none would reach min_frames = {self.data.min_frames}"
            )

    def recorded(self) -> dict[str, Any]:
        """The manifest's `config`: every field but the seed, which the manifest holds beside it."""
        return {k: v for k, v in to_dict(self).items() if k != "seed"}


def run_seeds(seed: int, split: str, index: int) -> tuple[int, int]:
    """(sensor-noise seed, OU seed) of one run, independent of every other run."""
    ss = np.random.SeedSequence(seed, spawn_key=(SPLITS.index(split), index))
    env_seed, policy_seed = ss.generate_state(2)
    return int(env_seed), int(policy_seed)


def collect_run(
    env: CanyonEnv, config: CollectConfig, seed: int, split: str, index: int, driver: Policy | None = None
) -> Run:
    """Drive one OU run until a bump, a contact, the time limit or `max_steps`.

    Every observation is a frame but the first `skip_frames`; a stored action is the yaw rate the
    robot was commanded after its frame (unclipped: samples clip it, `DataConfig.action_clip`).
    With a `driver` the command is its yaw rate plus the OU command (a DAgger round: the states the
    policy drives itself into, its actions as varied as the exploration's); the targets are the same.
    """
    env_seed, policy_seed = run_seeds(seed, split, index)
    canyon = CanyonId(split, index, config.env.world.family)
    policy = OUPolicy(config.ou, seed=policy_seed)
    if driver is not None:
        driver.reset(policy_seed)
    limit = config.env.world.max_yaw_rate
    obs, info = env.reset(seed=env_seed, options={"canyon": canyon})
    frames, actions, end_reason = [(obs, info)], [], "step_limit"
    for _ in range(config.max_steps):
        command = policy.act(obs) + (driver.act(obs) if driver is not None else 0.0)
        actions.append(float(np.clip(command, -limit, limit)))
        obs, _, terminated, truncated, info = env.step(np.array([actions[-1]], np.float32))
        frames.append((obs, info))
        if terminated or truncated:
            end_reason = info["end_reason"]
            break
    actions.append(np.nan)  # the last frame is where the run ended: no action
    keep = min(config.skip_frames, len(frames) - 1)  # a run that ended while skipping keeps its last frame
    frames, actions = frames[keep:], actions[keep:]
    meta = RunMeta(
        split=split,
        index=index,
        canyon_split=split,
        canyon_index=index,
        canyon_seed=int(canyon.seed_sequence.generate_state(1)[0]),
        policy_seed=policy_seed,
        end_reason=end_reason,
        n_frames=len(frames),
    )
    return Run(
        meta=meta,
        images=np.stack([o["image"] for o, _ in frames]),
        scans=np.stack([o["scan"] for o, _ in frames]),
        bins=np.stack([o["bins"] for o, _ in frames]),
        actions=np.asarray(actions, np.float32),
        poses=np.asarray([i["pose"] for _, i in frames], np.float32),
        times=np.asarray([i["time"] for _, i in frames], np.float32),
    )


def collect_and_write(
    env: CanyonEnv, config: CollectConfig, seed: int, root: Path, split: str, index: int,
    driver: Policy | None = None,
) -> tuple[RunMeta, FileInfo]:
    """One run collected (`collect_run`) and written to its file (not yet recorded: only the parent
    writes the manifest)."""
    run = collect_run(env, config, seed, split, index, driver)
    return run.meta, write_run(run_path(root, split, index), run, config.data.jpeg_quality)


class _CollectWorker:
    """One simulator collecting and writing run after run (a worker of `depthq.parallel`); only the
    parent writes the manifest."""

    def __init__(self, config: CollectConfig, seed: int, root: str) -> None:
        self.config, self.seed, self.root = config, seed, Path(root)
        self.env = CanyonEnv(config.env)

    def __call__(self, task: tuple[str, int]) -> tuple[RunMeta, FileInfo]:
        return collect_and_write(self.env, self.config, self.seed, self.root, *task)

    def close(self) -> None:
        self.env.close()


def collect(
    out: Path,
    config: CollectConfig,
    workers: int = 1,
    overwrite: bool = False,
    progress: bool = True,
    executor: Executor = LOCAL,
) -> Dataset:
    """Collect until each split holds `runs` / `val_runs` usable runs with no gap; resume what is there.

    Runs shorter than `data.min_frames` are kept on disk but do not count, so run indices continue
    past `runs` until the split has enough usable ones (the same indices whatever the workers).
    """
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    executor.check_shared(out)  # workers write the run files themselves
    dataset = Dataset.create(Path(out).resolve(), config.recorded(), config.seed, overwrite=overwrite,
                             look_images=look_images(config.env.world.look))
    wanted = {"train": config.runs, "val": config.val_runs}
    bar = Bar(
        total=sum(wanted.values()), desc="collect", unit="run", disable=not progress, dynamic_ncols=True
    )
    steps, start = 0, time.perf_counter()
    try:
        while todo := dataset.missing(wanted, config.data.min_frames):
            bar.n = sum(wanted.values()) - len(todo)
            bar.refresh()
            for meta, info in _run_all(todo, config, config.seed, dataset, workers, executor):
                dataset.add(meta, info)
                steps += meta.n_frames
                bar.update(usable(meta, config.data.min_frames))  # usable runs only, as `todo` counts
                bar.set_postfix(steps_per_s=f"{steps / (time.perf_counter() - start):.0f}")
    finally:
        bar.close()
    return dataset


def collection_complete(out: Path, config: CollectConfig) -> bool:
    """Whether `out` already holds every run `config` asks for (then `collect` has nothing to do)."""
    if not (Path(out) / "manifest.json").is_file():
        return False
    dataset = Dataset.open(Path(out))
    if dataset.config != config.recorded() or dataset.seed != config.seed:
        return False
    return not dataset.missing({"train": config.runs, "val": config.val_runs}, config.data.min_frames)


def _run_all(
    todo, config: CollectConfig, seed: int, dataset: Dataset, workers: int, executor: Executor
) -> Iterator[tuple[RunMeta, FileInfo]]:
    if workers == 1 and executor.kind == "local":  # in this process: no worker to start
        worker = _CollectWorker(config, seed, str(dataset.root))
        try:
            yield from (worker(task) for task in todo)
        finally:
            worker.close()
        return
    make_worker = partial(_CollectWorker, config, seed, str(dataset.root))
    for _, result in executor.run(make_worker, todo, workers, "collection"):
        yield result
