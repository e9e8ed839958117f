"""Evaluation speed: one policy driven in 20 canyons one canyon at a time, then in lock-step
(docs/design.md#lockstep), in the same workers; seconds, decisions per second, and whether the two
gave the same runs."""

from __future__ import annotations

import time
from dataclasses import replace

from depthq.blocks.device import resolve_device
from depthq.evaluate.online import EvalConfig, at_policy_rate, drive_canyons
from depthq.policies.spec import PolicySpec


def bench_evaluate(
    spec: PolicySpec,
    canyons: tuple[str, ...],
    workers: int = 2,
    time_limit_s: float | None = None,
    device: str = "auto",
    look: str | None = None,
) -> dict:
    """Wall seconds of `drive_canyons` for `spec` in `canyons` (in `look`; None: their family's own),
    sequential then lock-step: workers' start (processes, policy, simulators) and every run, no files
    written, no offline metric."""
    where = str(resolve_device(device))
    spec = spec.resolved()
    config = at_policy_rate(EvalConfig(canyons=canyons, time_limit_s=time_limit_s, look=look), spec)
    seconds, runs = {}, {}
    for name, lockstep in (("sequential", False), ("lockstep", True)):
        start = time.perf_counter()
        runs[name] = drive_canyons(spec, replace(config, lockstep=lockstep), workers, device=where)
        seconds[name] = time.perf_counter() - start
    decisions = sum(r["steps"] for r in runs["lockstep"])
    actions = [[r["actions"].tolist() for r in runs[name]] for name in seconds]
    return {
        "policy": spec.name,
        "canyons": len(canyons),
        "workers": workers,
        "decisions": decisions,
        **{f"{name}_s": round(s, 1) for name, s in seconds.items()},
        **{f"{name}_decisions_per_s": round(decisions / s, 1) for name, s in seconds.items()},
        "speedup": round(seconds["sequential"] / seconds["lockstep"], 2),
        "same_runs": actions[0] == actions[1],
    }
