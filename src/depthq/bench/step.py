"""Where one evaluation step's time goes, part by part, and the floor those parts set for lock-step
evaluation (docs/benchmarks.md#floor): no batching can make a step cheaper than rendering its frame,
passing that frame through the trunk and its candidates through the head."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import torch

from depthq.bench.policy import BATCH, untrained_depth_policy
from depthq.blocks.device import resolve_device
from depthq.blocks.trunk import preprocess
from depthq.control.heuristic import DepthHeuristic
from depthq.policies.qnet import BATCH_FRAMES, QNetPolicy
from depthq.sim.env import CanyonEnv, EnvConfig, parse_canyon
from depthq.sim.world import WorldConfig, world_for


def _ms(fn: Callable[[], object], repeats: int) -> float:
    """Median ms of `repeats` calls of `fn`, after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return float(np.median(times))


def bench_step(
    spec: str | None = None, canyon: str = "val:1000", steps: int = 50, device: str = "auto",
    threads: int = 1, look: str | None = None,
) -> dict:
    """Median ms of each part of a step on one process with `threads` torch threads (an evaluation
    worker has one): the simulator's (physics over one decision period, LiDAR ray cast, render,
    pixel noise) on `steps` steps of the heuristic expert's drive in `canyon`, and the policy's (`spec`, a
    checkpoint folder; None: a freshly initialised Depth-Q-Net of the default trunk, whose timing does
    not depend on its weights) on one frame alone and per frame in a batch of BATCH frames.

    `floor_ms_per_step` adds the simulator's parts and the policy's per-frame cost in a batch: what a
    lock-step step costs per canyon if nothing else took time. `batch_bound` is BATCH frames' policy
    cost over one decision's: the least a batch of BATCH decisions can cost, in decisions."""
    canyon_id = parse_canyon(canyon)  # a bad canyon fails before the trunk is built
    torch.set_num_threads(threads)
    where = str(resolve_device(device))
    policy = QNetPolicy.from_checkpoint(spec, device=where) if spec else untrained_depth_policy(where)
    world = world_for(WorldConfig(), canyon_id.family)  # in `look`, or the canyon family's own
    world = world if look is None else replace(world, look=look)
    env = CanyonEnv(EnvConfig(world=world, time_limit_s=1e6))
    env.reset(seed=0, options={"canyon": canyon_id})
    world, rng, expert = env.world, np.random.default_rng(0), DepthHeuristic()
    parts: dict[str, list[float]] = {"physics": [], "lidar": [], "render": [], "noise": []}
    action = 0.0
    for _ in range(steps):  # the parts of `CanyonEnv.step`, one at a time, the expert steering
        marks = [time.perf_counter()]
        world.advance(action)
        marks.append(time.perf_counter())
        scan = world.scan(rng)
        marks.append(time.perf_counter())
        world.render()
        marks.append(time.perf_counter())
        world.image(rng)  # a render plus its noise
        marks.append(time.perf_counter())
        for name, start, end in zip(parts, marks[:-1], marks[1:], strict=True):
            parts[name].append((end - start) * 1e3)
        action = expert.act({"scan": scan})
    frames = [world.image(rng).copy() for _ in range(BATCH)]
    env.close()
    sim = {name: float(np.median(ms)) for name, ms in parts.items()}
    sim["noise"] = max(0.0, sim["noise"] - sim["render"])  # `image` is a render plus its noise
    repeats = max(3, steps // 10)
    with torch.inference_mode():
        one = policy.features(frames[:1])
        batch = torch.cat([one] * BATCH)
        net, observations = policy.net, [{"image": f} for f in frames]
        x_one = preprocess(np.stack(frames[:1]), policy.input_size).to(policy.device)
        x_chunk = preprocess(np.stack(frames[:BATCH_FRAMES]), policy.input_size).to(policy.device)
        nets = {
            "trunk_one": _ms(lambda: net.trunk(x_one), repeats),
            "trunk_in_batch": _ms(lambda: net.trunk(x_chunk), repeats) / BATCH_FRAMES,
            "head_one": _ms(lambda: policy.candidate_values(one), repeats),
            "head_in_batch": _ms(lambda: policy.candidate_values(batch), repeats) / BATCH,
            "decision_one": _ms(lambda: policy.act({"image": frames[0]}), repeats),
            "decision_in_batch": _ms(lambda: policy.act_batch(observations), repeats) / BATCH,
        }
    per_frame = nets["trunk_in_batch"] + nets["head_in_batch"]
    floor = sum(sim.values()) + per_frame
    return {
        "policy": policy.name,
        "canyon": str(canyon_id),
        "threads": threads,
        "steps": steps,
        "batch": BATCH,
        "sim_ms": {k: round(v, 3) for k, v in sim.items()},
        "policy_ms": {k: round(v, 3) for k, v in nets.items()},
        "floor_ms_per_step": round(floor, 2),
        "batch_bound": round(BATCH * per_frame / nets["decision_one"], 2),
    }
