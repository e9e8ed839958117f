"""ROS 1 and ROS 2 bags: a dataset out as a bag a ROS user can open, a robot's recording in as a dataset."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.errors import ConfigError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    # No defaults here: depthq.data.rosbag needs the optional rosbags package, so its Topics and
    # ImportConfig fill in what is not given (the TurtleBot3's topic names, a 1 s gap, 1 val run).
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    out = actions.add_parser("export", help="a dataset's runs as a bag (rosbag2 MCAP or SQLite3, or ROS 1)")
    out.add_argument("data", type=Path, help="dataset folder")
    out.add_argument("--out", type=Path, required=True, help="new bag folder, or file *.bag for ros1")
    out.add_argument("--format", "--storage", dest="format", default="mcap",  # --storage: the old name
                     help="mcap (default), sqlite3 or ros1 (a .bag file)")
    into = actions.add_parser("import", help="a robot's recording (ROS 1 or rosbag2) as a new dataset folder")
    into.add_argument("bag", type=Path, help="a ROS 1 *.bag file or a rosbag2 folder (with metadata.yaml)")
    into.add_argument("--out", type=Path, required=True, help="new dataset folder")
    into.add_argument("--image-topic", help="camera topic (default /camera/image_raw/compressed)")
    into.add_argument("--scan-topic", help="LiDAR topic (default /scan; '' imports a camera-only recording)")
    into.add_argument("--cmd-topic", help="command topic (default /cmd_vel)")
    into.add_argument("--odom-topic", help="odometry topic (default /odom; '' imports without poses)")
    into.add_argument("--max-gap", type=float, help="seconds between frames that end a run (default 1)")
    into.add_argument("--val-runs", type=int, help="the last N runs form the val split, at least one run "
                      "left to train (default 1; 0 for a recording of one run)")


def run(args: argparse.Namespace) -> int:
    try:
        from depthq.data import rosbag  # needs the optional [ros] extra (rosbags)
    except ModuleNotFoundError as err:
        if err.name != "rosbags":
            raise
        raise ConfigError('depthq bag needs the rosbags package: pip install "depthq[ros]"') from None
    if args.action == "export":
        path = rosbag.export_bag(args.data, args.out, bag_format=args.format)
        print(f"wrote {path}")
        return 0
    given = {
        "image": args.image_topic,
        "scan": args.scan_topic,
        "cmd": args.cmd_topic,
        "odom": args.odom_topic,
    }
    topics = rosbag.Topics(**{k: v for k, v in given.items() if v is not None})
    given = {"max_gap_s": args.max_gap, "val_runs": args.val_runs}
    config = rosbag.ImportConfig(topics=topics, **{k: v for k, v in given.items() if v is not None})
    dataset = rosbag.import_bag(args.bag, args.out, config)
    entries = dataset.entries()
    print(
        f"wrote {args.out}: {len(entries)} runs ({len(dataset.entries('val'))} val), "
        f"{sum(e.n_frames for e in entries)} frames; check it with `depthq dataset stats {args.out}`"
    )
    return 0
