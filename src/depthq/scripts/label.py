"""Write depth bins estimated from the camera beside the LiDAR's, into every run of a dataset (resumable)."""

from __future__ import annotations

import argparse
from pathlib import Path

SOURCES = ("camera",)  # where the estimated bins come from


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dir", type=Path, help="dataset folder whose runs get the labels")
    p.add_argument("--from", dest="source", choices=SOURCES, required=True,
                   help="what the bins are estimated from: camera (each stored frame)")
    p.add_argument("--labeller", type=Path, required=True,
                   help="labeller folder (`depthq labeller`)")
    p.add_argument("--replace", action="store_true",
                   help="replace labels another labeller wrote (refused otherwise, so none are mixed)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(_writes=("dir",))  # the dataset it labels: locked while it does


def run(args: argparse.Namespace) -> int:
    from depthq.data.manifest import Dataset
    from depthq.labellers.labeller import label_dataset, load_labeller

    dataset = Dataset.open(args.dir)
    labeller = load_labeller(args.labeller)
    written, kept = label_dataset(dataset, labeller, args.replace, progress=not args.no_progress)
    print(f"{dataset.root}: camera labels written in {written} runs, {kept} already there "
          f"(labeller {labeller.record['name']}, fingerprint {labeller.fingerprint[:16]}…)")
    return 0
