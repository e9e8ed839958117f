"""Measure the speed targets of SPEC §4 (benchmarks, never timed tests)."""

from __future__ import annotations

import argparse
import json

from depthq.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="what", required=True, metavar="WHAT")
    sim = sub.add_parser("sim", help="env steps/s with camera + LiDAR at full resolution")
    sim.add_argument("--steps", type=int, default=1000, help="steps per worker")
    sim.add_argument("--workers", type=int, default=1)
    sim.add_argument("--json", action="store_true")


def _positive(name: str, value: int) -> None:
    if value <= 0:
        raise ConfigError(f"{name} must be > 0, got {value}")


def run(args: argparse.Namespace) -> int:
    if args.what == "sim":
        _positive("--steps", args.steps)
        _positive("--workers", args.workers)
        from depthq.sim.bench import bench_sim

        result = bench_sim(args.steps, args.workers)
        if args.json:
            print(json.dumps(result))
        else:
            print(
                f"{result['workers']} worker(s), {result['steps']} steps in {result['seconds']} s, "
                f"max RSS {result['max_rss_mb']} MB per process"
            )
            print(f"{result['steps_per_s']} env steps/s")
    return 0
