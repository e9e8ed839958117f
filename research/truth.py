"""The simulator's truth at a dataset's recorded frames: from each frame's stored pose, the noise-free
bins one decision later for each candidate action (`depthq.evaluate.oracle`'s one-step depth oracle),
re-simulated in the dataset's own canyons (the family and decision rate its manifest records)."""

from __future__ import annotations

import numpy as np

from depthq.data.manifest import Dataset
from depthq.errors import ConfigError
from depthq.evaluate.oracle import Oracle, OracleWorld, env_config
from depthq.sim.canyon import CanyonId

ONE_STEP = Oracle()  # the true next bins of each candidate: a perfect one-step Depth-Q-Net


def family(dataset: Dataset) -> str:
    """The canyon family the dataset was collected in (its manifest's env.world; the paper's if unset)."""
    found = dataset.family()
    if found is None:
        raise ConfigError(f"{dataset.root}: a robot's recording has no canyons to re-simulate")
    return found


def canyon(dataset: Dataset, split: str, run_id: int) -> str:
    """The name of the canyon a run of `split` drove in."""
    return str(CanyonId(split, run_id, family(dataset)))


def dataset_world(dataset: Dataset) -> OracleWorld:
    """A noise-free world of the dataset's family at its decision rate."""
    rate = float(dataset.config["env"]["world"]["decision_hz"])
    return OracleWorld(env_config([canyon(dataset, "val", 0)], rate))


def next_bins(
    dataset: Dataset, split: str, run_ids: np.ndarray, frame_ids: np.ndarray, cache: dict | None = None
) -> np.ndarray:
    """(S, len(ACTIONS), bins): from the pose of each sample (run, frame) of `split`, the true bins one
    decision later with each candidate action. `cache` keeps them per frame, so runs over other
    samples of the same dataset (a checkpoint of another target horizon) reuse what they share."""
    cache = {} if cache is None else cache
    keys = [(str(dataset.root), split, int(r), int(t)) for r, t in zip(run_ids, frame_ids, strict=True)]
    missing = [key for key in dict.fromkeys(keys) if key not in cache]
    if missing:
        sim, loaded, poses = dataset_world(dataset), None, np.empty(0)
        try:
            for key in missing:
                _, _, run_id, t = key
                if run_id != loaded:
                    sim.load(canyon(dataset, split, run_id))
                    poses = dataset.read_run(dataset.entry(split, run_id), images=False).poses
                    loaded = run_id
                cache[key] = sim.truth(ONE_STEP, poses[t].astype(np.float64))[0][:, 0]
        finally:
            sim.close()
    return np.stack([cache[key] for key in keys]).astype(np.float32)
