"""Decision latency of a Q-net policy: one camera frame in, one action out (3 candidate actions); and
a batch of frames in one call, as lock-step evaluation decides for 20 canyons (docs/design.md#lockstep)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from depthq.blocks.device import resolve_device
from depthq.blocks.heads import QNet
from depthq.blocks.trunk import build_trunk
from depthq.control.policy import BatchPolicy
from depthq.networks import DepthQNet, build_head
from depthq.parallel import cores
from depthq.policies.qnet import QNetPolicy
from depthq.policies.registry import make_policy
from depthq.policies.spec import PolicySpec
from depthq.sim.env import CanyonEnv
from depthq.train.config import TrainConfig

BATCH = 20  # the evaluation canyons: one lock-step step of a single worker


def bench_policy(
    specs: list[PolicySpec] | None = None,
    decisions: int = 200,
    device: str = "auto",
    batches: int | None = None,
    threads: int | None = None,
    acting: Mapping[str, Any] | None = None,
) -> dict:
    """Median and 90th-percentile ms per decision on real rendered frames, for each policy in `specs`
    (checkpoint folders or 'onnx:PATH'), taken in turns on the same frames so they compare fairly;
    then, for a `BatchPolicy`, `batches` calls of `act_batch` on BATCH frames (None: as many decisions
    as `decisions`, at least one call): ms per call and per decision in it. `threads`: torch's and an
    ONNX session's (None: this process's cores, onnxruntime's default; an evaluation worker has one).
    `acting`: the policies' acting settings by network name (`EvalConfig.acting`; None: the
    defaults), e.g. a lookahead Depth-Q-Net's `switch`, its largest candidate set.

    Without `specs` the policy gets a freshly initialised Depth-Q-Net head: the latency does not
    depend on the weights, only on the trunk and the head's shape.
    """
    where = str(resolve_device(device))
    torch.set_num_threads(threads or cores())
    batches = max(1, decisions // BATCH) if batches is None else batches
    if specs:
        policies = [make_policy(spec, device=where, acting=acting, threads=threads) for spec in specs]
    else:
        policies = [untrained_depth_policy(where)]
    env = CanyonEnv()
    obs, _ = env.reset(seed=0, options={"canyon": "eval:0"})
    frames = []
    for _ in range(BATCH):  # real frames from a drive, reused
        frames.append(obs)
        obs, *_ = env.step(np.zeros(1, np.float32))
    env.close()
    for policy in policies:
        for obs in frames[:5]:  # warm-up
            policy.act(obs)
        if isinstance(policy, BatchPolicy):
            policy.act_batch(frames)
    times = [[] for _ in policies]
    for k in range(decisions):
        for policy, ms in zip(policies, times, strict=True):
            start = time.perf_counter()
            policy.act(frames[k % len(frames)])
            ms.append((time.perf_counter() - start) * 1e3)
    batch_times = [[] for _ in policies]
    for _ in range(batches):
        for policy, ms in zip(policies, batch_times, strict=True):
            if isinstance(policy, BatchPolicy):
                start = time.perf_counter()
                policy.act_batch(frames)
                ms.append((time.perf_counter() - start) * 1e3)
    return {
        "threads": torch.get_num_threads(),
        "decisions": decisions,
        "batch": BATCH,
        "batches": batches,
        "policies": [
            {
                "policy": policy.name,
                "candidates": len(policy.candidates),  # actions, or sequences of a lookahead net
                "ms_median": round(float(np.median(ms)), 2),
                "ms_p90": round(float(np.percentile(ms, 90)), 2),
                **_batch_figures(batch_ms),
            }
            for policy, ms, batch_ms in zip(policies, times, batch_times, strict=True)
        ],
    }


def untrained_depth_policy(device: str) -> QNetPolicy:
    """A freshly initialised Depth-Q-Net as `depthq train --model depth` builds it by default: a
    policy's latency depends on the trunk and the head's shape, not on the weights."""
    config = TrainConfig(model=DepthQNet.name, data="-")  # its defaults; no data: nothing is trained
    net = QNet(build_trunk(config.trunk), build_head(config.head()))
    return QNetPolicy(net, DepthQNet.name, device=device)


def _batch_figures(ms: list[float]) -> dict:
    """A policy's batch timings: ms per `act_batch` call (median, p90) and per decision in it; none
    for a policy without the call."""
    if not ms:
        return {}
    median = float(np.median(ms))
    return {
        "batch_ms_median": round(median, 2),
        "batch_ms_p90": round(float(np.percentile(ms, 90)), 2),
        "batch_ms_per_decision": round(median / BATCH, 2),
    }
