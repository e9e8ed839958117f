"""Inspect a dataset folder: the paper's Table II (`stats`) or a full integrity check (`verify`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.stats import dataset_stats, format_stats

_DEFAULTS = DataConfig()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    stats = actions.add_parser("stats", help="runs and samples of every nested subset (Table II)")
    stats.add_argument("dir", type=Path, help="dataset folder")
    stats.add_argument("--json", action="store_true", help="print JSON instead of a table")
    stats.add_argument("--horizon", type=int, default=_DEFAULTS.horizon, help="collision label horizon H")
    stats.add_argument(
        "--min-frames", type=int, default=_DEFAULTS.min_frames, help="shorter runs are left out"
    )
    verify = actions.add_parser("verify", help="read every run file and check it against the manifest")
    verify.add_argument("dir", type=Path, help="dataset folder")


def run(args: argparse.Namespace) -> int:
    dataset = Dataset.open(args.dir)
    if args.action == "stats":
        stats = dataset_stats(dataset, DataConfig(horizon=args.horizon, min_frames=args.min_frames))
        print(json.dumps(stats, indent=2) if args.json else format_stats(stats))
        return 0
    problems = dataset.verify(progress=True)
    for problem in problems:
        print(problem, file=sys.stderr)
    if problems:
        print(f"{args.dir}: {len(problems)} problem(s) found", file=sys.stderr)
        return 1
    entries = dataset.entries()
    print(f"OK: {args.dir}: {len(entries)} runs, {sum(e.n_frames for e in entries)} frames verified")
    return 0
