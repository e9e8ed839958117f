"""Would a policy decide in bf16? Its decisions and time under bfloat16 autocast against float32.

    python docs/precision.py CHECKPOINT [CHECKPOINT ...]

On up to 1000 frames of the checkpoint's dataset's validation runs (every other frame of its first
40 runs), one torch thread, one frame per decision: the share of decisions bf16 changes, and ms per
decision in each precision (the best of two passes each, taken in turns). docs/benchmarks.md#precision.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import torch

import depthq  # noqa: F401  (MUJOCO_GL before mujoco)
from depthq.control.qnet_policy import QNetPolicy
from depthq.data.manifest import Dataset
from depthq.nets.checkpoint import dataset_record, read_config
from depthq.nets.heads import probability

FRAMES = 1000


def val_frames(data: Path) -> list[np.ndarray]:
    dataset = Dataset.open(data)
    frames = []
    for entry in dataset.entries("val")[:40]:
        with dataset.reader(entry) as reader:
            frames += [reader.image(t) for t in range(0, entry.n_frames, 2)]
    return frames[:FRAMES]


@torch.inference_mode()
def decide(policy: QNetPolicy, frame: np.ndarray, bf16: bool) -> float:
    """The policy's action for `frame`, its trunk and head under bf16 autocast when `bf16`."""
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        out = policy.net.candidate_outputs(policy.features([frame]), policy._actions_t)[0].float()
    return policy.choose((probability(out) if policy.kind == "coll" else out).numpy())


def main(checkpoints: list[str]) -> None:
    torch.set_num_threads(1)
    for folder in checkpoints:
        policy = QNetPolicy.from_checkpoint(Path(folder))
        frames = val_frames(Path(dataset_record(read_config(Path(folder))).path))
        times: dict[str, list[float]] = {"fp32": [], "bf16": []}
        actions = {}
        for precision in ("fp32", "bf16", "fp32", "bf16"):
            start = time.perf_counter()
            actions[precision] = [decide(policy, f, precision == "bf16") for f in frames]
            times[precision].append((time.perf_counter() - start) / len(frames) * 1e3)
        assert actions["fp32"][:50] == [policy.act({"image": f}) for f in frames[:50]], "not the policy's own"
        changed = sum(a != b for a, b in zip(actions["fp32"], actions["bf16"], strict=True))
        print(f"{policy.name}: {len(frames)} val frames, bf16 changes {changed} decisions "
              f"({changed / len(frames):.1%}); ms per decision: fp32 {min(times['fp32']):.2f}, "
              f"bf16 {min(times['bf16']):.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
