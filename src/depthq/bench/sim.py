"""Simulator throughput: env steps/s with camera and LiDAR at full resolution, in W processes, per look
(measured one look after the other in one call, so that they share the machine's load)."""

from __future__ import annotations

import multiprocessing as mp
import resource
import time
from dataclasses import replace

import numpy as np

from depthq.control.ou import OUPolicy
from depthq.sim.canyon import PAPER
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.world import WorldConfig, world_for


def _worker(steps: int, seed: int, queue, family: str, look: str | None) -> None:
    world = world_for(WorldConfig(), family)
    env = CanyonEnv(EnvConfig(world=world if look is None else replace(world, look=look)))
    policy = OUPolicy(seed=seed)
    index = seed * 10_000
    canyon = lambda i: f"{'' if family == PAPER else family + '/'}train:{i}"  # noqa: E731
    env.reset(seed=seed, options={"canyon": canyon(index)})
    obs, _ = env.reset(seed=seed, options={"canyon": canyon(index)})  # warm, then time
    start = time.perf_counter()
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(np.array([policy.act(obs)], np.float32))
        if terminated or truncated:
            index += 1
            obs, _ = env.reset(options={"canyon": canyon(index)})
            policy.reset()
    elapsed = time.perf_counter() - start
    env.close()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    queue.put((steps, elapsed, rss_mb))


def bench_sim(steps: int = 1000, workers: int = 1, family: str = PAPER,
              looks: tuple[str | None, ...] = (None,)) -> dict:
    """Steps/s in each of `looks` (None: the family's own), one after the other; with one look, its
    figures alone (`bench_look`), else one entry per look and each look's steps/s over the first's."""
    if looks == (None,) or len(looks) == 1:
        return bench_look(steps, workers, family, looks[0])
    each = {look: bench_look(steps, workers, family, look) for look in looks}
    first = each[looks[0]]["steps_per_s"]
    return {"looks": each, "relative": {look: round(r["steps_per_s"] / first, 3) for look, r in each.items()}}


def bench_look(steps: int, workers: int, family: str, look: str | None) -> dict:
    """Aggregate steps/s over `workers` processes (spawned: EGL contexts do not survive a fork)."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(steps, w, queue, family, look)) for w in range(workers)]
    for p in procs:
        p.start()
    results = [queue.get() for _ in procs]
    for p in procs:
        p.join()
    total = sum(r[0] for r in results)
    wall = max(r[1] for r in results)
    return {
        "family": family,
        "look": look or "the family's own",
        "workers": workers,
        "steps": total,
        "seconds": round(wall, 3),
        "steps_per_s": round(total / wall, 1),
        "steps_per_s_per_worker": [round(r[0] / r[1], 1) for r in results],
        "max_rss_mb": round(max(r[2] for r in results), 1),
    }
