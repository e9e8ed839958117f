"""Collect exploration runs (OU policy) in fresh training canyons into a dataset folder."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from depthq.parallel import add_executor_arguments, executor_from


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", type=int, default=900, help="training runs")
    p.add_argument("--val-runs", type=int, default=90, help="validation runs (their own canyons)")
    p.add_argument("--workers", type=int, default=2, help="parallel worker processes")
    p.add_argument("--seed", type=int, default=0, help="collection seed (sensor and OU noise)")
    p.add_argument(
        "--max-steps", type=int, default=600, help="cut a run that never bumps after this many steps"
    )
    p.add_argument("--hz", type=float, default=None, help="decisions (camera frames) per second")
    p.add_argument("--out", type=Path, required=True, help="dataset folder (created, or resumed)")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset made with another config")
    add_executor_arguments(p)


def run(args: argparse.Namespace) -> int:
    from depthq.data.collect import CollectConfig, collect, exploration_env
    from depthq.data.stats import dataset_stats, format_stats

    env = exploration_env() if args.hz is None else exploration_env(args.hz)
    config = CollectConfig(runs=args.runs, val_runs=args.val_runs, max_steps=args.max_steps, env=env)
    start = time.perf_counter()
    executor = executor_from(args)
    dataset = collect(args.out, config, args.seed, args.workers, args.overwrite, executor=executor)
    elapsed = time.perf_counter() - start
    size = sum(p.stat().st_size for p in (args.out / "runs").glob("*.h5"))
    frames = sum(e.n_frames for e in dataset.entries())
    print(format_stats(dataset_stats(dataset, config.data)))
    print(
        f"{len(dataset.entries())} runs, {frames} frames, {size / 2**20:.1f} MiB "
        f"({size / max(frames, 1) / 1024:.1f} KiB per frame) in {args.out}; this call took {elapsed:.1f} s"
    )
    return 0
