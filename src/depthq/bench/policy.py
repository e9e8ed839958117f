"""Decision latency of a Q-net policy: one camera frame in, one action out (3 candidate actions)."""

from __future__ import annotations

import time

import numpy as np
import torch

from depthq.control.qnet_policy import QNetPolicy
from depthq.control.registry import make_policy
from depthq.nets.device import resolve_device
from depthq.nets.heads import HeadConfig, QNet, build_head
from depthq.nets.trunk import DEFAULT_TRUNK, build_trunk
from depthq.parallel import cores
from depthq.sim.env import CanyonEnv


def bench_policy(specs: list[str] | None = None, decisions: int = 200, device: str = "auto") -> dict:
    """Median and 90th-percentile ms per decision on real rendered frames, for each policy in `specs`
    (checkpoint folders or 'onnx:PATH'), taken in turns on the same frames so they compare fairly.

    Without `specs` the policy gets a freshly initialised Depth-Q-Net head: the latency does not
    depend on the weights, only on the trunk and the head's shape.
    """
    where = str(resolve_device(device))
    torch.set_num_threads(cores())
    if specs:
        policies = [make_policy(spec, device=where) for spec in specs]
    else:
        trunk = build_trunk(DEFAULT_TRUNK)
        head = build_head(HeadConfig("depth", trunk.feature_dim))
        policies = [QNetPolicy(QNet(trunk, head), "depth", device=where)]
    env = CanyonEnv()
    obs, _ = env.reset(seed=0, options={"canyon": "eval:0"})
    frames = []
    for _ in range(20):  # real frames from a drive, reused
        frames.append(obs)
        obs, *_ = env.step(np.zeros(1, np.float32))
    env.close()
    for policy in policies:
        for obs in frames[:5]:  # warm-up
            policy.act(obs)
    times = [[] for _ in policies]
    for k in range(decisions):
        for policy, ms in zip(policies, times, strict=True):
            start = time.perf_counter()
            policy.act(frames[k % len(frames)])
            ms.append((time.perf_counter() - start) * 1e3)
    return {
        "threads": torch.get_num_threads(),
        "decisions": decisions,
        "policies": [
            {
                "policy": policy.name,
                "ms_median": round(float(np.median(ms)), 2),
                "ms_p90": round(float(np.percentile(ms, 90)), 2),
            }
            for policy, ms in zip(policies, times, strict=True)
        ],
    }
