"""Simulator throughput: env steps/s with camera and LiDAR at full resolution, in W processes, per look
(each worker steps every look's env in turns of CHUNK steps, so that the looks share the machine's
load even as it changes during the call)."""

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

CHUNK = 50  # steps of one look before the next look's turn (a canyon lasts a few dozen steps)


def _worker(steps: int, seed: int, queue, family: str, looks: tuple[str | None, ...]) -> None:
    """`steps` OU-driven steps in each look, in turns, each look through the same canyons; puts
    (steps, seconds) per look and the process's peak RSS (all its looks' envs)."""
    world = world_for(WorldConfig(), family)
    prefix = "" if family == PAPER else family + "/"
    envs = [CanyonEnv(EnvConfig(world=world if look is None else replace(world, look=look)))
            for look in looks]
    policies = [OUPolicy(seed=seed) for _ in looks]
    index = [seed * 10_000] * len(looks)
    first = {"canyon": f"{prefix}train:{seed * 10_000}"}
    obs = []
    for env in envs:
        env.reset(seed=seed, options=first)
        obs.append(env.reset(seed=seed, options=first)[0])  # warm, then time
    done, elapsed = [0] * len(looks), [0.0] * len(looks)
    while min(done) < steps:
        for k, (env, policy) in enumerate(zip(envs, policies, strict=True)):
            n = min(CHUNK, steps - done[k])
            start = time.perf_counter()
            for _ in range(n):
                obs[k], _, terminated, truncated, _ = env.step(np.array([policy.act(obs[k])], np.float32))
                if terminated or truncated:
                    index[k] += 1
                    obs[k], _ = env.reset(options={"canyon": f"{prefix}train:{index[k]}"})
                    policy.reset()
            elapsed[k] += time.perf_counter() - start
            done[k] += n
    for env in envs:
        env.close()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    queue.put((list(zip(done, elapsed, strict=True)), rss_mb))


def bench_sim(steps: int = 1000, workers: int = 1, family: str = PAPER,
              looks: tuple[str | None, ...] = (None,)) -> dict:
    """Steps/s in each of `looks` (None: the family's own), aggregated over `workers` processes
    (spawned: EGL contexts do not survive a fork); with one look, its figures alone, else one entry
    per look and each look's steps/s over the first's."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(steps, w, queue, family, looks)) for w in range(workers)]
    for p in procs:
        p.start()
    results = [queue.get() for _ in procs]
    for p in procs:
        p.join()
    rss = round(max(r[1] for r in results), 1)
    each = []
    for k, look in enumerate(looks):
        per_worker = [r[0][k] for r in results]
        total, wall = sum(s for s, _ in per_worker), max(t for _, t in per_worker)
        each.append({
            "family": family,
            "look": look or "the family's own",
            "workers": workers,
            "steps": total,
            "seconds": round(wall, 3),
            "steps_per_s": round(total / wall, 1),
            "steps_per_s_per_worker": [round(s / t, 1) for s, t in per_worker],
            "max_rss_mb": rss,
        })
    if len(looks) == 1:
        return each[0]
    first = each[0]["steps_per_s"]
    return {"looks": {e["look"]: e for e in each},
            "relative": {e["look"]: round(e["steps_per_s"] / first, 3) for e in each}}
