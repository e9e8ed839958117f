"""The monodepth labeller with and without brightness compensation in its photometric loss (issue #57,
item 4): each setting's labeller learnt on a dataset, its error against the LiDAR on `val` runs.

    python -m research.labeller_brightness OUT --data DATA [--data DATA2 ...] [--measure DATA3 ...]
        [--brightness none,affine] [--steps 1500] [--seed 0] [--gains]

Per dataset of `--data` and per setting of `--brightness`, a monodepth labeller (today's defaults but
`brightness`, `steps` and `seed`) learns on the dataset's training runs into OUT/<data>_<setting>_s<seed>;
then its estimates of the `val` runs of that dataset and of every `--measure` dataset (other looks of
the same camera and robot: a labeller learnt in one look read in another) are scored against their
LiDAR as `depthq dataset stats` scores camera labels (`depthq.data.stats.label_errors`: the nearest
bin's and the bands' median and mean absolute error), into OUT/<labeller>/error_<dataset>.json. No
dataset is written to. Every labeller and every score is kept once written: a stopped run resumes. The
last step prints the table of the nearest bin's median error (m) per labeller and dataset. `--gains`
also prints how far a warped neighbour's brightness is from its frame's (`pair_gains`): what there is to
compensate.

A finished investigation (research/, not in the wheel; run from a checkout's root); its numbers are in
docs/research/camera_labels.md#brightness.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import kornia
import numpy as np
import torch

from depthq.configio import from_dict, read_json, write_json
from depthq.data.manifest import Dataset
from depthq.data.stats import label_errors
from depthq.errors import ConfigError, guarded
from depthq.labellers import monodepth
from depthq.labellers.floor import BATCH
from depthq.labellers.labeller import LabellerConfig, check_applicable, load_labeller, train_labeller
from depthq.labellers.monodepth import Brightness

PROG = "python -m research.labeller_brightness"
SETTINGS: tuple[str, ...] = Brightness.__args__


def val_error(folder: Path, data: Path) -> dict[str, Any]:
    """The labeller in `folder` against the LiDAR of `data`'s val runs (`label_errors`), kept in
    folder/error_<data's name>.json once written."""
    path = folder / f"error_{data.name}.json"
    if path.is_file():
        return read_json(path)
    dataset, labeller = Dataset.open(data), load_labeller(folder)
    check_applicable(labeller, dataset)
    lidar, camera = [], []
    entries = dataset.entries("val")
    for entry in entries:
        run = dataset.read_run(entry, images=True)
        lidar.append(run.bins)
        camera.append(labeller.estimate(run))
    record = {"labeller": str(folder), "data": str(data.resolve()),
              **label_errors(np.concatenate(lidar), np.concatenate(camera), len(entries))}
    write_json(path, record)
    return record


def pair_gains(folder: Path, data: Path, pairs_per_run: int = 2) -> dict[str, Any]:
    """How much a neighbour's brightness differs from its frame's where the labeller in `folder` warps it
    (`data`'s val runs, `pairs_per_run` random triplets each, seed 0): per pair and channel the gain
    `compensate` would fit ("gain": the ratio of the means over the pixels the warp sees), as |log|
    median and 90th percentile, its colour part (red and blue against green), and the photometric
    error that gain compensation takes off (median per pair)."""
    dataset, labeller = Dataset.open(data), load_labeller(folder)
    estimate, config = labeller.estimate, from_dict(LabellerConfig, labeller.record["config"])
    triplets, transforms = monodepth._pool(dataset, dataset.entries("val"), estimate.geo,
                                           replace(config, pool_frames=pairs_per_run),
                                           np.random.default_rng(0), False)
    camera = monodepth.intrinsics(estimate.geo)[None]
    gains, cut = [], []
    with torch.inference_mode():
        for i in range(0, len(triplets), BATCH):
            frames = torch.from_numpy(triplets[i : i + BATCH].astype(np.float32))
            target = frames[:, 1]
            depth = monodepth.depth_of(estimate.net(target)[0], *estimate.depth_range)
            for k in (0, 1):
                source = torch.cat([frames[:, 2 * k], torch.ones_like(target[:, :1])], dim=1)
                warped = kornia.geometry.depth.warp_frame_depth(
                    source, depth, torch.from_numpy(transforms[i : i + BATCH, k]),
                    camera.expand(len(target), 3, 3))
                seen = warped[:, 3:] > 1 - 1e-3
                weight, image = seen.float(), warped[:, :3]
                count = weight.sum((2, 3)).clamp_min(1.0)
                gains.append(((target * weight).sum((2, 3)) / (image * weight).sum((2, 3)).clamp_min(1e-6))
                             .numpy())
                errors = [(monodepth.photometric(x, target) * weight).sum((1, 2, 3)) / count[:, 0]
                          for x in (image, monodepth.compensate(image, target, seen, "gain"))]
                cut.append((errors[0] - errors[1]).numpy())
    ratios = np.log(np.concatenate(gains))
    log, colour = np.abs(ratios), np.abs(ratios[:, [0, 2]] - ratios[:, [1]])
    def rounded(values: np.ndarray) -> list[float]:
        return [round(float(v), 4) for v in values]

    return {"pairs": len(log), "log_gain_median": rounded(np.median(log, axis=0)),
            "log_gain_p90": rounded(np.percentile(log, 90, axis=0)),
            "colour_median": rounded(np.median(colour, axis=0)),
            "error_cut_median": round(float(np.median(np.concatenate(cut))), 5)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="folder of the labellers and their errors (resumed)")
    parser.add_argument("--data", type=Path, action="append", required=True,
                        help="a dataset a labeller of each setting learns on and is scored on (repeatable)")
    parser.add_argument("--measure", type=Path, action="append", default=[],
                        help="a dataset every labeller is also scored on, its val runs (repeatable)")
    parser.add_argument("--brightness", default="none,affine",
                        help=f"settings to compare, comma-separated, of {', '.join(SETTINGS)}")
    parser.add_argument("--steps", type=int, default=None, help="optimiser steps (none: the default's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--gains", action="store_true",
                        help="also print, per labeller, how much its warped neighbours' brightness "
                             "differs from their frames' on its own dataset's val runs (`pair_gains`)")
    args = parser.parse_args(argv)

    def work() -> int:
        settings = args.brightness.split(",")
        if bad := [s for s in settings if s not in SETTINGS]:
            raise ConfigError(f"--brightness {', '.join(bad)}: not one of {', '.join(SETTINGS)}")
        rows = []
        for data in args.data:
            for setting in settings:
                config = LabellerConfig(data=str(data.resolve()), brightness=setting, steps=args.steps,
                                        seed=args.seed)
                folder = args.out / f"{data.name}_{setting}_s{args.seed}"
                print(f"labeller {folder.name}", flush=True)
                train_labeller(config, folder, progress=True)
                errors = [val_error(folder, d) for d in [data, *args.measure]]
                rows.append((folder.name, [e["nearest"]["median"] for e in errors],
                             [d.name for d in [data, *args.measure]]))
                if args.gains:
                    print(f"{folder.name} on {data.name}: {pair_gains(folder, data)}", flush=True)
        for name, medians, names in rows:
            print(f"{name}: nearest-bin median error (val) " +
                  ", ".join(f"{n} {m:.3f} m" for n, m in zip(names, medians, strict=True)))
        return 0

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
