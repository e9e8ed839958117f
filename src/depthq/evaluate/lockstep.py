"""Lock-step evaluation (docs/design.md#lockstep): the runs a worker drives advance together, one
step of every live run at a time, so that a `BatchPolicy` decides for all of them in one call (a
Q-net: one trunk pass over all their frames). A run that ends drops out and the others go on.

Each run has its own env and seeds, and a `BatchPolicy` gives each frame the decision `act` gives
it alone, so every run is the one `depthq.evaluate.online.drive` gives: the same actions, the same
records. A policy without a batch call, or with per-run state (OU noise), drives each run with an
instance of its own, one `act` at a time.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from depthq.control.policy import BatchPolicy, Policy
from depthq.errors import ConfigError
from depthq.evaluate.run_record import RunRecord
from depthq.sim.env import CanyonEnv, parse_canyon


@dataclass(frozen=True)
class Lane:
    """One run to drive: its canyon, its seed (sensor noise; a stateful policy's too), and whether it
    keeps Fig. 4 snapshots (every `keep_every` decisions) and video frames (`RunRecord`)."""

    canyon: str
    seed: int
    keep_every: int = 0
    video: bool = False


def lane_policies(policy: Policy, make: Callable[[], Policy], n: int) -> list[Policy]:
    """A policy per run for `n` runs: `policy` itself for every run if it is a `BatchPolicy`, else
    `policy` and n − 1 more instances from `make`."""
    if isinstance(policy, BatchPolicy):
        return [policy] * n
    return [policy, *(make() for _ in range(n - 1))]


def drive_lockstep(
    policies: Sequence[Policy], envs: Sequence[CanyonEnv], expert: Policy, lanes: Sequence[Lane]
) -> list[dict[str, Any]]:
    """Drive `lanes[i]` with `policies[i]` in `envs[i]`, all in lock-step; the runs' records
    (`RunRecord.result`) in `lanes`' order. When every run has the same `BatchPolicy`, one
    `act_batch` call per step decides for all live runs, and each run counts the call's time
    divided by their number as its decision time; otherwise each policy acts for its own run."""
    if not len(policies) == len(envs) == len(lanes) > 0:
        raise ConfigError(
            f"lock-step needs one policy and one env per run, got {len(policies)} policies, "
            f"{len(envs)} envs, {len(lanes)} runs"
        )
    shared = isinstance(policies[0], BatchPolicy) and all(p is policies[0] for p in policies)
    batch = policies[0] if shared else None
    observations, records, results = [], [], [None] * len(lanes)
    for policy, env, lane in zip(policies, envs, lanes, strict=True):
        obs, info = env.reset(seed=lane.seed, options={"canyon": parse_canyon(lane.canyon)})
        policy.reset(lane.seed)
        observations.append(obs)
        records.append(RunRecord(lane.canyon, info, lane.keep_every, lane.video))
    live = list(range(len(lanes)))
    while live:
        expert_actions = [expert.act(observations[i]) for i in live]
        if batch is not None:
            start = time.perf_counter()
            actions = batch.act_batch([observations[i] for i in live])
            ms = [(time.perf_counter() - start) * 1e3 / len(live)] * len(live)
            values = getattr(batch, "last_batch_values", None) or [None] * len(live)
        else:
            actions, ms, values = [], [], []
            for i in live:
                start = time.perf_counter()
                actions.append(policies[i].act(observations[i]))
                ms.append((time.perf_counter() - start) * 1e3)
                values.append(getattr(policies[i], "last_values", None))
        for j, i in enumerate(live):
            env = envs[i]
            action = float(np.clip(actions[j], env.action_space.low[0], env.action_space.high[0]))
            before = observations[i]
            observations[i], _, terminated, truncated, info = env.step(np.array([action], np.float32))
            records[i].add(before, expert_actions[j], action, ms[j], values[j], observations[i], info)
            if terminated or truncated:
                results[i] = records[i].result(info)
        live = [i for i in live if results[i] is None]
    return results
