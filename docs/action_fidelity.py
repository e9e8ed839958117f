"""Does a Depth-Q-Net rank the actions as the simulator would? Measured on validation frames only.

    python docs/action_fidelity.py CHECKPOINT [CHECKPOINT ...]

For every validation frame of the checkpoint's dataset (its stored pose, its `val` canyon), the
simulator gives the true next bins for each of −1, 0, +1 (noise-free, one decision period); the
network gives its predictions from the frame's cached feature. Printed per checkpoint:

- L1 of the predicted bins against the true ones (near bins only), per action;
- `spread`: the mean range over actions of the nearest predicted / true obstacle, i.e. how much the
  action matters to the network and to the world;
- `agree`: how often the network's chosen action (max over actions of the nearest bin) is also the
  oracle's choice, among frames where the oracle's actions differ by more than 5 cm;
- `corr`: correlation of predicted and true (nearest obstacle of +1 minus that of −1).

A network whose L1 is good but whose spread is small and agreement near chance has learned the
scene, not the effect of its action: that is what limits the policy, not the depth itself.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

import depthq  # noqa: F401  (MUJOCO_GL before mujoco)
from depthq.configio import from_dict
from depthq.control.action_selection import depth_scores
from depthq.data.manifest import Dataset
from depthq.data.views import view_arrays
from depthq.nets.checkpoint import load_qnet
from depthq.sim.canyon import CanyonId, generate_canyon
from depthq.sim.sensors import LidarConfig, depth_bins, finish_scan
from depthq.sim.world import CanyonWorld, WorldConfig
from depthq.train.config import TrainConfig
from depthq.train.features import load_features

ACTIONS = (-1.0, 0.0, 1.0)


def true_next_bins(dataset: Dataset, arrays: dict[str, np.ndarray]) -> np.ndarray:
    """(S, 3, 26) noise-free next bins of every sample for each action, re-simulated from its pose."""
    rate = dataset.config["env"]["world"]["decision_hz"]
    world = CanyonWorld(WorldConfig(decision_hz=rate), render=False)
    exact = LidarConfig(noise_std=0.0)
    rng = np.random.default_rng(0)
    out = np.zeros((len(arrays["frame_id"]), len(ACTIONS), 26), np.float32)
    loaded, poses = None, {}
    for i, (run_id, t) in enumerate(zip(arrays["run_id"].tolist(), arrays["frame_id"].tolist(), strict=True)):
        if run_id != loaded:
            world.load(generate_canyon(CanyonId("val", run_id)))
            poses = dataset.read_run(dataset.entry("val", run_id), images=False).poses
            loaded = run_id
        for k, a in enumerate(ACTIONS):
            world.place(*poses[t].astype(float))
            world.advance(a)
            out[i, k] = depth_bins(finish_scan(world.raycast(), exact, rng))
    world.close()
    return out


def fidelity(checkpoint: Path, truth_cache: dict) -> dict[str, float]:
    net, record = load_qnet(checkpoint)
    config = from_dict(TrainConfig, record["train"])
    dataset = Dataset.open(Path(config.data))
    arrays = view_arrays(dataset, "val", None, "depth", config.labels())
    key = str(dataset.root)
    if key not in truth_cache:
        truth_cache[key] = true_next_bins(dataset, arrays)
    truth = truth_cache[key]
    features = load_features(dataset, config.trunk, config.input_size, progress=False).gather("val", arrays)
    with torch.no_grad():
        pred = np.stack(
            [net.head(features.float(), torch.full((len(features),), a)).numpy() for a in ACTIONS], axis=1
        )
    near = truth < 2.0 - 1e-6
    l1 = [float(np.abs(pred[:, k] - truth[:, k])[near[:, k]].mean()) for k in range(len(ACTIONS))]
    p_score = np.stack([depth_scores(p) for p in pred])  # (S, 3) nearest predicted obstacle per action
    t_score = np.stack([depth_scores(t) for t in truth])
    decisive = np.ptp(t_score, axis=1) > 0.05
    agree = float((p_score.argmax(1) == t_score.argmax(1))[decisive].mean())
    corr = float(np.corrcoef(p_score[:, 2] - p_score[:, 0], t_score[:, 2] - t_score[:, 0])[0, 1])
    return {
        "l1_left_straight_right": [round(v, 3) for v in l1],
        "spread_pred": round(float(np.ptp(p_score, axis=1).mean()), 3),
        "spread_true": round(float(np.ptp(t_score, axis=1).mean()), 3),
        "agree": round(agree, 3),
        "decisive_frames": int(decisive.sum()),
        "corr": round(corr, 3),
    }


if __name__ == "__main__":
    cache: dict = {}
    for folder in sys.argv[1:]:
        print(Path(folder).name, fidelity(Path(folder), cache))
