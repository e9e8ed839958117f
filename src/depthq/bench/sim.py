"""Simulator throughput: env steps/s with camera and LiDAR at full resolution, in W processes."""

from __future__ import annotations

import multiprocessing as mp
import resource
import time

import numpy as np

from depthq.control.ou import OUPolicy
from depthq.sim.env import CanyonEnv


def _worker(steps: int, seed: int, queue) -> None:
    env = CanyonEnv()
    policy = OUPolicy(seed=seed)
    index = seed * 10_000
    env.reset(seed=seed, options={"canyon": ("train", index)})
    obs, _ = env.reset(seed=seed, options={"canyon": ("train", index)})  # warm, then time
    start = time.perf_counter()
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(np.array([policy.act(obs)], np.float32))
        if terminated or truncated:
            index += 1
            obs, _ = env.reset(options={"canyon": ("train", index)})
            policy.reset()
    elapsed = time.perf_counter() - start
    env.close()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    queue.put((steps, elapsed, rss_mb))


def bench_sim(steps: int = 1000, workers: int = 1) -> dict:
    """Aggregate steps/s over `workers` processes (spawned: EGL contexts do not survive a fork)."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(steps, w, queue)) for w in range(workers)]
    for p in procs:
        p.start()
    results = [queue.get() for _ in procs]
    for p in procs:
        p.join()
    total = sum(r[0] for r in results)
    wall = max(r[1] for r in results)
    return {
        "workers": workers,
        "steps": total,
        "seconds": round(wall, 3),
        "steps_per_s": round(total / wall, 1),
        "steps_per_s_per_worker": [round(r[0] / r[1], 1) for r in results],
        "max_rss_mb": round(max(r[2] for r in results), 1),
    }
