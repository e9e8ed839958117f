"""Does a Depth-Q-Net rank the actions as the simulator would? Measured on validation frames only.

    python -m research.action_fidelity CHECKPOINT [CHECKPOINT ...]

For every validation frame of the checkpoint's dataset (its stored pose, its `val` canyon in the
dataset's own family), the simulator gives the true next bins for each of −1, 0, +1 (noise-free,
one decision period at the data's rate: `research.truth`); the network gives its
predictions from the frame's cached feature. Printed per checkpoint:

- L1 of the predicted bins against the true ones (near bins only), per action;
- `spread`: the mean range over actions of the nearest predicted / true obstacle, i.e. how much the
  action matters to the network and to the world;
- `agree`: how often the network's chosen action (max over actions of the nearest bin) is also the
  oracle's choice, among frames where the oracle's actions differ by more than 5 cm;
- `corr`: correlation of predicted and true (nearest obstacle of +1 minus that of −1).

A network whose L1 is good but whose spread is small and agreement near chance has learned the
scene, not the effect of its action: that is what limits the policy, not the depth itself.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/val_choices.md came from the code of commit b1f0d44 (2026-11-22: the last change of that page's
tables).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

from depthq.checkpoint import load_qnet
from depthq.configio import from_dict
from depthq.control.action_selection import ACTIONS, depth_scores
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target
from depthq.data.views import view_arrays
from depthq.train.config import TrainConfig
from depthq.train.features import load_features
from research.truth import next_bins


def fidelity(checkpoint: Path, truth_cache: dict | None = None) -> dict[str, Any]:
    """The measures above for one Depth-Q-Net checkpoint; `truth_cache` shares the simulator's truth
    between checkpoints of the same dataset (per frame: their sample sets may differ)."""
    net, record = load_qnet(checkpoint)
    config = from_dict(TrainConfig, record["train"])
    dataset = Dataset.open(Path(config.data))
    arrays = view_arrays(dataset, "val", None, bins_target, config.samples)
    truth = next_bins(dataset, "val", arrays["run_id"], arrays["frame_id"], truth_cache)
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.action_fidelity",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("checkpoints", type=Path, nargs="+", help="Depth-Q-Net checkpoint folders")
    args = parser.parse_args(argv)
    cache: dict = {}
    for folder in args.checkpoints:
        print(folder.name, fidelity(folder, cache), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
