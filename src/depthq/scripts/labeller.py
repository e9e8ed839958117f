"""Train a camera labeller (a frame → its 26 depth bins) for `depthq label`: from the camera and odometry
(floor, monodepth), or from another canyon family's LiDAR (perception)."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.blocks.device import DEVICE_HELP
from depthq.flags import add_config_arguments, config_from_args


def add_arguments(p: argparse.ArgumentParser) -> None:
    from depthq.labellers.labeller import LabellerConfig  # torch: when this verb's flags are built

    p.add_argument("--out", type=Path, required=True, help="labeller folder (created; a finished one kept)")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_config_arguments(p, LabellerConfig)


def run(args: argparse.Namespace) -> int:
    from depthq.labellers.labeller import CAMERA_METHODS, LabellerConfig, read_record, train_labeller

    config = config_from_args(LabellerConfig, args)
    out = train_labeller(config, args.out, progress=not args.no_progress, device=args.device)
    record = read_record(out)
    family = record["source"]["family"]
    if record["name"] in CAMERA_METHODS:
        print(f"labeller: {out} ({record['name']}, fingerprint {record['fingerprint'][:16]}…), learnt from "
              f"the {family!r} family's camera and odometry; training loss {record['losses'][0]:.3f} → "
              f"{record['losses'][-1]:.3f}, val loss {record['val_loss']:.3f}")
        print(f"label a dataset of this camera with: depthq label DATA --from camera --labeller {out}")
    else:
        print(f"labeller: {out} (perception, fingerprint {record['fingerprint'][:16]}…), learnt from the "
              f"{family!r} family's LiDAR; training loss {record['losses'][0]:.3f} → "
              f"{record['losses'][-1]:.3f} m, val L1 {record['val_l1']:.3f} m")
        print(f"label another family's dataset with: depthq label DATA --from camera --labeller {out}")
    return 0
