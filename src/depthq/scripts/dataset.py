"""Inspect a dataset folder: Table II and the camera labels' error (`stats`), or its integrity (`verify`);
or add its runs rendered again in other looks (`rerender`)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.stats import stats_report
from depthq.flags import add_config_arguments, config_from_args
from depthq.parallel import add_executor_arguments, executor_from


def add_arguments(parser: argparse.ArgumentParser) -> None:
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    stats = actions.add_parser("stats", help="runs and samples of every nested subset (Table II), and the "
                               "camera labels' error against the LiDAR where runs hold both")
    stats.add_argument("dir", type=Path, help="dataset folder")
    stats.add_argument("--json", action="store_true", help="print JSON instead of a table")
    add_config_arguments(stats, DataConfig)
    verify = actions.add_parser("verify", help="read every run file and check it against the manifest, "
                                "every re-rendered run against its source, every feature cache against its "
                                "checksum, and that the folder holds every run its collection config asks "
                                "for")
    verify.add_argument("dir", type=Path, help="dataset folder")
    again = actions.add_parser(
        "rerender", help="add every collected run rendered again in other looks: the same poses, LiDAR, "
        "bins, actions and end, new frames (and, in the textured looks, a new canyon appearance and camera), "
        "one run each in the same split (docs/formats.md#re-rendered-runs); resumed when stopped")
    again.add_argument("dir", type=Path, help="dataset folder")
    again.add_argument("--looks", required=True,
                       help="looks, comma-separated: flat, colours, textured, heldout, broad or folders of "
                       "images (docs/design.md#looks), e.g. broad,textured")
    again.add_argument("--seed", type=int, default=1,
                       help="which draw of each look's canyon appearance, pixel noise and camera: another "
                       "seed adds another draw [%(default)s]")
    again.add_argument("--workers", type=int, default=2, help="parallel worker processes [%(default)s]")
    add_executor_arguments(again)
    again.set_defaults(_writes=("dir",))  # the dataset it adds to: locked while it does


def run(args: argparse.Namespace) -> int:
    if args.action == "rerender":
        return _rerender(args)
    dataset = Dataset.open(args.dir)
    if args.action == "stats":
        record, text = stats_report(dataset, config_from_args(DataConfig, args))
        print(json.dumps(record, indent=2) if args.json else text)
        return 0
    from depthq.data.rerender import verify_rendered  # MuJoCo: only for verify
    from depthq.train.features import verify_caches  # torch: only for verify

    problems = dataset.verify(progress=True) + verify_rendered(dataset) + verify_caches(dataset)
    for problem in problems:
        print(problem, file=sys.stderr)
    if problems:
        print(f"{args.dir}: {len(problems)} problem(s) found", file=sys.stderr)
        return 1
    entries = dataset.entries()
    print(f"OK: {args.dir}: {len(entries)} runs, {sum(e.n_frames for e in entries)} frames verified")
    return 0


def _rerender(args: argparse.Namespace) -> int:
    from depthq.data.rerender import rerender  # MuJoCo: only when this action runs

    looks = tuple(look.strip() for look in args.looks.split(",") if look.strip())
    start = time.perf_counter()
    dataset = rerender(args.dir, looks, args.seed, args.workers, executor=executor_from(args))
    rendered = [e for e in dataset.entries() if e.rendered is not None]
    elapsed = time.perf_counter() - start
    print(f"{args.dir}: {len(dataset.entries()) - len(rendered)} collected runs, {len(rendered)} re-rendered "
          f"({sum(e.n_frames for e in rendered)} frames); this call took {elapsed:.1f} s")
    return 0
