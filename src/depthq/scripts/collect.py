"""Collect exploration runs (OU policy) in fresh training canyons into a dataset folder."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from depthq.data import DataConfig
from depthq.data.stats import dataset_stats, format_stats
from depthq.flags import add_config_arguments, config_from_args
from depthq.parallel import add_executor_arguments, executor_from

# CollectConfig's flags as `depthq collect` spelled them before they were made from it, kept as aliases.
_ALIASES = {"env.world.decision_hz": ("--hz",), "env.world.family": ("--family",),
            "env.world.look": ("--look",)}
_HELP = {"env.world.family": "docs/hard_canyons.md; its canyon generator and look are the defaults of "
         "--env.world.canyon.* and --look",
         "env.world.look": "default: the family's own"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, default=2, help="parallel worker processes")
    p.add_argument("--out", type=Path, required=True, help="dataset folder (created, or resumed)")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset made with another config")
    add_executor_arguments(p)
    from depthq.data.recorder import CollectConfig  # MuJoCo: only when this verb's flags are built

    add_config_arguments(p, CollectConfig, aliases=_ALIASES, more_help=_HELP)


def run(args: argparse.Namespace) -> int:
    from depthq.data.recorder import CollectConfig, collect, exploration_env  # MuJoCo: when this verb runs
    from depthq.sim.canyon import PAPER

    # The family's world first (its canyon generator and look), then every flag given on top of it.
    family = getattr(args, "env.world.family", PAPER)
    config = config_from_args(CollectConfig, args, base=CollectConfig(env=exploration_env(family=family)))
    start = time.perf_counter()
    executor = executor_from(args)
    dataset = collect(args.out, config, args.workers, args.overwrite, executor=executor)
    elapsed = time.perf_counter() - start
    size = sum(p.stat().st_size for p in (args.out / "runs").glob("*.h5"))
    frames = sum(e.n_frames for e in dataset.entries())
    # Table II as a training counts it by default, of the runs that count as collected.
    print(format_stats(dataset_stats(dataset, DataConfig(min_frames=config.data.min_frames))))
    print(
        f"{len(dataset.entries())} runs, {frames} frames, {size / 2**20:.1f} MiB "
        f"({size / max(frames, 1) / 1024:.1f} KiB per frame) in {args.out}; this call took {elapsed:.1f} s"
    )
    return 0
