"""The checks behind docs/results.md#before-10 ("What this shows"): why Depth-Q-Net steered towards
walls on our data.

    python docs/investigation.py runs/quick/data

1. sign check: after a saturated left (right) turn, does the next scan's content move right (left)?
2. one-step oracle: the selection rule with the simulator's true next scan for each action.
3. constant baseline: validation L1 of the per-bin median of the training targets.
4. action effect: the true one-step effect of the action per bin (re-simulated from stored poses)
   against the slope of next-step depth on the action in the OU data.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import depthq  # noqa: F401  (MUJOCO_GL before mujoco)
from depthq.control.action_selection import select_depth_action
from depthq.data.manifest import Dataset
from depthq.data.views import view_arrays
from depthq.sim.canyon import CanyonId, generate_canyon
from depthq.sim.env import CanyonEnv
from depthq.sim.sensors import LidarConfig, depth_bins, finish_scan
from depthq.sim.world import CanyonWorld

ACTIONS = np.array([-1.0, 0.0, 1.0])
EXACT = LidarConfig(noise_std=0.0)


def next_bins(world: CanyonWorld, pose: np.ndarray, action: float) -> np.ndarray:
    """The noise-free bins one decision after `pose` with `action`."""
    world.place(*pose.astype(float))
    world.advance(action)
    return depth_bins(finish_scan(world.raycast(), EXACT, np.random.default_rng(0)))


def sign_check(dataset: Dataset, runs: int = 60) -> dict[int, float]:
    moved_right = {1: [], -1: []}
    for entry in dataset.entries("train")[:runs]:
        run = dataset.read_run(entry, images=False)
        b = np.nan_to_num(run.bins, nan=2.0)
        for t in np.flatnonzero(np.abs(run.actions[:-1]) > 0.9):
            right = np.abs(b[t + 1, 2:] - b[t, :-2]).mean() < np.abs(b[t + 1, :-2] - b[t, 2:]).mean()
            moved_right[int(np.sign(run.actions[t]))].append(right)
    return {a: float(np.mean(v)) for a, v in moved_right.items()}


def oracle_distances(canyons: int = 10) -> list[float]:
    env = CanyonEnv()
    distances = []
    for k in range(canyons):
        _, info = env.reset(seed=k, options={"canyon": f"eval:{k}"})
        done = False
        while not done:
            pose = env.world.pose
            preds = np.nan_to_num([next_bins(env.world, pose, a) for a in ACTIONS], nan=0.0)
            env.world.place(*pose)
            _, _, terminated, truncated, info = env.step([select_depth_action(preds, ACTIONS)])
            done = terminated or truncated
        distances.append(round(info["distance"], 1))
    env.close()
    return distances


def constant_baseline(dataset: Dataset) -> float:
    near = {split: view_arrays(dataset, split, None, kind="depth")["target"] for split in ("train", "val")}
    valid = {k: np.isfinite(v) & (v < 2.0 - 1e-6) for k, v in near.items()}
    median = np.nanmedian(np.where(valid["train"], near["train"], np.nan), axis=0)
    return float(np.abs(median - near["val"])[valid["val"]].mean())


def action_effects(dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
    world = CanyonWorld(render=False)
    effect = []
    for entry in dataset.entries("val"):
        run = dataset.read_run(entry, images=False)
        world.load(generate_canyon(CanyonId("val", entry.index)))
        for t in range(0, run.n_frames - 6, 3):
            effect.append((next_bins(world, run.poses[t], 1.0) - next_bins(world, run.poses[t], -1.0)) / 2)
    v = view_arrays(dataset, "train", None, kind="depth")
    target = np.where(np.isfinite(v["target"]), v["target"], 2.0)
    slope = np.array([np.polyfit(v["action"], target[:, k], 1)[0] for k in range(target.shape[1])])
    return np.nanmean(effect, axis=0), slope


if __name__ == "__main__":
    data = Dataset.open(Path(sys.argv[1]))
    np.set_printoptions(precision=3, suppress=True, linewidth=200)
    print("fraction of saturated turns whose next scan moved right (+1) / right (-1):", sign_check(data))
    print("one-step oracle, distance in eval:0-9 (m):", oracle_distances())
    print("validation L1 of the per-bin median (m):", round(constant_baseline(data), 3))
    true_effect, data_slope = action_effects(data)
    print("true one-step d(bins)/da:", true_effect)
    print("OU data slope of next bins on a:", data_slope)
