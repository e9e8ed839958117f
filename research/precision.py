"""Would a policy decide in bf16? Its decisions and time under bfloat16 autocast against float32.

    python -m research.precision CHECKPOINT [CHECKPOINT ...]

On up to 1000 frames of the checkpoint's dataset's validation runs (every other frame of its first
40 runs), one torch thread, one frame per decision: the share of decisions bf16 changes, and ms per
decision in each precision (the best of two passes each, taken in turns). docs/benchmarks.md#precision.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/benchmarks.md#precision came from the code of commit 6c50adb (2026-11-23: the last change of that
page's tables).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from depthq.checkpoint import dataset_record, read_config
from depthq.data.manifest import Dataset
from depthq.networks import get_network
from depthq.policies.qnet import QNetPolicy

FRAMES = 1000


def val_frames(data: Path, frames: int = FRAMES) -> list[np.ndarray]:
    """Every other frame of the first 40 validation runs, at most `frames`."""
    dataset = Dataset.open(data)
    out = []
    for entry in dataset.entries("val")[:40]:
        with dataset.reader(entry) as reader:
            out += [reader.image(t) for t in range(0, entry.n_frames, 2)]
    return out[:frames]


@torch.inference_mode()
def decide(policy: QNetPolicy, candidates: torch.Tensor, frame: np.ndarray, bf16: bool) -> float:
    """The policy's action for `frame` among `candidates`, its trunk and head under bf16 autocast
    when `bf16`."""
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        out = policy.net.candidate_outputs(policy.features([frame]), candidates)[0].float()
    return policy.choose(get_network(policy.kind).output(out).numpy())


def measure(checkpoint: Path, frames: int = FRAMES) -> dict[str, Any]:
    """The decisions bf16 changes on the checkpoint's validation frames, and ms per decision."""
    policy = QNetPolicy.from_checkpoint(checkpoint)
    images = val_frames(Path(dataset_record(read_config(checkpoint)).path), frames)
    candidates = torch.tensor(policy.candidates, dtype=torch.float32)
    times: dict[str, list[float]] = {"fp32": [], "bf16": []}
    actions = {}
    for precision in ("fp32", "bf16", "fp32", "bf16"):
        start = time.perf_counter()
        actions[precision] = [decide(policy, candidates, f, precision == "bf16") for f in images]
        times[precision].append((time.perf_counter() - start) / len(images) * 1e3)
    assert actions["fp32"][:50] == [policy.act({"image": f}) for f in images[:50]], "not the policy's own"
    changed = sum(a != b for a, b in zip(actions["fp32"], actions["bf16"], strict=True))
    return {"policy": policy.name, "frames": len(images), "changed": changed,
            "fp32_ms": min(times["fp32"]), "bf16_ms": min(times["bf16"])}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.precision",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("checkpoints", type=Path, nargs="+", help="checkpoint folders (`depthq train`)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    for folder in args.checkpoints:
        r = measure(folder)
        print(f"{r['policy']}: {r['frames']} val frames, bf16 changes {r['changed']} decisions "
              f"({r['changed'] / r['frames']:.1%}); ms per decision: fp32 {r['fp32_ms']:.2f}, "
              f"bf16 {r['bf16_ms']:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
