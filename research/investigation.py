"""The checks behind docs/research/history.md#before-10 ("What this shows"): why Depth-Q-Net steered
towards walls on our data.

    python -m research.investigation runs/quick/data

1. sign check: after a saturated left (right) turn, does the next scan's content move right (left)?
2. one-step oracle (`depthq.evaluate.oracle`): the selection rule with the simulator's true next scan
   for each action, driven in eval:0-9.
3. constant baseline: validation L1 of the per-bin median of the training targets.
4. action effect: the true one-step effect of the action per bin (re-simulated from stored poses in
   the dataset's own canyons) against the slope of next-step depth on the action in the OU data.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/research/history.md#before-10 came from the code of commit 396f92d
(2026-11-23: the last change of those tables).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from depthq.control.action_selection import ACTIONS
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target
from depthq.data.views import view_arrays
from depthq.evaluate.oracle import Oracle, drive_oracle
from depthq.sim.world import WorldConfig
from research.truth import next_bins

ORACLE_CANYONS = tuple(f"eval:{k}" for k in range(10))


def sign_check(dataset: Dataset, runs: int = 60) -> dict[int, float]:
    """Per sign of a saturated turn, the share of next scans whose content moved right."""
    moved_right: dict[int, list[bool]] = {1: [], -1: []}
    for entry in dataset.entries("train")[:runs]:
        run = dataset.read_run(entry, images=False)
        b = np.nan_to_num(run.bins, nan=2.0)
        for t in np.flatnonzero(np.abs(run.actions[:-1]) > 0.9):
            right = np.abs(b[t + 1, 2:] - b[t, :-2]).mean() < np.abs(b[t + 1, :-2] - b[t, 2:]).mean()
            moved_right[int(np.sign(run.actions[t]))].append(right)
    return {a: float(np.mean(v)) for a, v in moved_right.items()}


def oracle_distances(canyons: tuple[str, ...] = ORACLE_CANYONS) -> list[float]:
    """The one-step oracle's distance (m) in each canyon, at the default decision rate."""
    runs = drive_oracle(Oracle(), list(canyons), WorldConfig().decision_hz)["runs"]
    return [round(r["distance"], 1) for r in runs]


def constant_baseline(dataset: Dataset) -> float:
    """Validation L1 (m, near bins) of the per-bin median of the training targets."""
    near = {split: view_arrays(dataset, split, None, target=bins_target)["target"]
            for split in ("train", "val")}
    valid = {k: np.isfinite(v) & (v < 2.0 - 1e-6) for k, v in near.items()}
    median = np.nanmedian(np.where(valid["train"], near["train"], np.nan), axis=0)
    return float(np.abs(median - near["val"])[valid["val"]].mean())


def action_effects(dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Per bin, the true d(bins)/da of one decision (every third frame of the val runs) and the OU
    data's slope of next-step depth on the action."""
    run_ids, frame_ids = [], []
    for entry in dataset.entries("val"):
        frames = range(0, entry.n_frames - 6, 3)
        run_ids += [entry.index] * len(frames)
        frame_ids += list(frames)
    truth = next_bins(dataset, "val", np.array(run_ids, int), np.array(frame_ids, int))
    effect = (truth[:, ACTIONS.index(1.0)] - truth[:, ACTIONS.index(-1.0)]) / 2
    v = view_arrays(dataset, "train", None, target=bins_target)
    target = np.where(np.isfinite(v["target"]), v["target"], 2.0)
    slope = np.array([np.polyfit(v["action"], target[:, k], 1)[0] for k in range(target.shape[1])])
    return np.nanmean(effect, axis=0), slope


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.investigation",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("data", type=Path, help="a dataset folder (`depthq collect`)")
    args = parser.parse_args(argv)
    data = Dataset.open(args.data)
    np.set_printoptions(precision=3, suppress=True, linewidth=200)
    print("fraction of saturated turns whose next scan moved right (+1) / right (-1):", sign_check(data))
    print("one-step oracle, distance in eval:0-9 (m):", oracle_distances())
    print("validation L1 of the per-bin median (m):", round(constant_baseline(data), 3))
    true_effect, data_slope = action_effects(data)
    print("true one-step d(bins)/da:", true_effect)
    print("OU data slope of next bins on a:", data_slope)
    return 0


if __name__ == "__main__":
    sys.exit(main())
