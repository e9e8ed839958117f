"""Decision latency of a Q-net policy: one camera frame in, one action out (3 candidate actions)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from depthq.control.qnet_policy import QNetPolicy
from depthq.parallel import cores


def bench_policy(checkpoint: Path | None = None, decisions: int = 200, device: str = "auto") -> dict:
    """Median and 90th-percentile ms per decision on real rendered frames.

    Without a checkpoint the policy gets a freshly initialised Depth-Q-Net head: the latency does not
    depend on the weights, only on the trunk and the head's shape.
    """
    from depthq.nets.device import resolve_device
    from depthq.nets.heads import HeadConfig, QNet, build_head
    from depthq.nets.trunk import DEFAULT_TRUNK, build_trunk
    from depthq.sim.env import CanyonEnv

    where = resolve_device(device)
    torch.set_num_threads(cores())
    if checkpoint is not None:
        policy = QNetPolicy.from_checkpoint(Path(checkpoint), device=where)
    else:
        trunk = build_trunk(DEFAULT_TRUNK)
        head = build_head(HeadConfig("depth", trunk.feature_dim))
        policy = QNetPolicy(QNet(trunk, head), "depth", device=where)
    env = CanyonEnv()
    obs, _ = env.reset(seed=0, options={"canyon": "eval:0"})
    frames = []
    for _ in range(20):  # real frames from a drive, reused
        frames.append(obs)
        obs, *_ = env.step(np.zeros(1, np.float32))
    env.close()
    for obs in frames[:5]:  # warm-up
        policy.act(obs)
    times = []
    for k in range(decisions):
        start = time.perf_counter()
        policy.act(frames[k % len(frames)])
        times.append((time.perf_counter() - start) * 1e3)
    return {
        "policy": policy.name,
        "threads": torch.get_num_threads(),
        "decisions": decisions,
        "ms_median": round(float(np.median(times)), 2),
        "ms_p90": round(float(np.percentile(times, 90)), 2),
    }
