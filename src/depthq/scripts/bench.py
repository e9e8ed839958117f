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
    col = sub.add_parser("collect", help="collection steps/s with storage, 1 and W workers")
    col.add_argument("--runs", type=int, default=20)
    col.add_argument("--workers", type=int, default=2)
    col.add_argument("--json", action="store_true")


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
    if args.what == "collect":
        _positive("--runs", args.runs)
        _positive("--workers", args.workers)
        from depthq.data.bench import bench_collect

        result = bench_collect(args.runs, tuple(sorted({1, args.workers})))
        if args.json:
            print(json.dumps(result))
        else:
            for key, r in result.items():
                if key.startswith("w"):
                    print(
                        f"{key[1:]} worker(s): {r['frames']} frames in {r['seconds']} s, "
                        f"{r['steps_per_s_per_worker']} steps/s per worker, {r['kb_per_frame']} KB per frame"
                    )
            if "speedup" in result:
                print(f"speedup {result['speedup']}x")
            last = result[f"w{args.workers}"]
            print(f"{last['steps_per_s']} steps/s stored with {args.workers} worker(s)")
    return 0
