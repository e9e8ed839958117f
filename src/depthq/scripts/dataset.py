"""Inspect a dataset folder: Table II and the camera labels' error (`stats`), or its integrity (`verify`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.stats import stats_report
from depthq.flags import add_config_arguments, config_from_args


def add_arguments(parser: argparse.ArgumentParser) -> None:
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    stats = actions.add_parser("stats", help="runs and samples of every nested subset (Table II), and the "
                               "camera labels' error against the LiDAR where runs hold both")
    stats.add_argument("dir", type=Path, help="dataset folder")
    stats.add_argument("--json", action="store_true", help="print JSON instead of a table")
    add_config_arguments(stats, DataConfig)
    verify = actions.add_parser("verify", help="read every run file and check it against the manifest, every "
                                "feature cache against its checksum, and that the folder holds every run "
                                "its collection config asks for")
    verify.add_argument("dir", type=Path, help="dataset folder")


def run(args: argparse.Namespace) -> int:
    dataset = Dataset.open(args.dir)
    if args.action == "stats":
        record, text = stats_report(dataset, config_from_args(DataConfig, args))
        print(json.dumps(record, indent=2) if args.json else text)
        return 0
    from depthq.train.features import verify_caches  # torch: only for verify

    problems = dataset.verify(progress=True) + verify_caches(dataset)
    for problem in problems:
        print(problem, file=sys.stderr)
    if problems:
        print(f"{args.dir}: {len(problems)} problem(s) found", file=sys.stderr)
        return 1
    entries = dataset.entries()
    print(f"OK: {args.dir}: {len(entries)} runs, {sum(e.n_frames for e in entries)} frames verified")
    return 0
