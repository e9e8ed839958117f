"""Which distance band's camera-label errors cost a camera-label Depth-Q-Net its driving (issue #32):
the camera labels of a `camera_labels` experiment with the LiDAR's bins put in where the LiDAR reads
nearer than `split` m ("near") or not nearer ("far"), a Depth-Q-Net trained on each mix as on the camera
labels, driven in the same canyons. A diagnostic: its labels use the LiDAR, no labeller would.

    python -m research.label_bands run OUT --band near|far [--split 1.0] [--seeds 0]

OUT is a `python -m research.camera_labels run` folder (its floor labels, setup and sweep);
this writes OUT/bands/<band>_<split>/data (OUT/floor/data hard-linked, its labels replaced), models/
and eval/, as the camera-label experiment lays them out, and prints that experiment's rows for them.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/research/camera_labels.md came from the code of commit 05758a2
(2026-11-26: the last change of those tables).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from depthq.configio import read_json
from depthq.data.camera_labels import CameraLabels
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError, guarded
from depthq.pipeline.layout import model_name
from depthq.pipeline.sweep import parse_ints
from depthq.report.cells import mean_interval
from depthq.train.trainer import train
from research.camera_labels import (
    SUMMARY,
    camera_config,
    evaluate_once,
    link_copy,
    parse_settings,
    read_setup,
)

PROG = "python -m research.label_bands"
BANDS = ("near", "far")
NAME = "floor+lidar"  # the mixed labels' labeller name: not a labeller's


def mixed(lidar: np.ndarray, camera: np.ndarray, band: str, split: float) -> np.ndarray:
    """`camera` bins with the valid LiDAR bins of `band` put in: near, the LiDAR under `split` m; far,
    the LiDAR at `split` m or more."""
    with np.errstate(invalid="ignore"):
        take = np.isfinite(lidar) & ((lidar < split) if band == "near" else (lidar >= split))
    return np.where(take, lidar, camera).astype(np.float32)


def write_mix(source: Path, target: Path, band: str, split: float, progress: bool = True) -> Dataset:
    """`source` (camera-labelled) hard-linked to `target`, each run's labels replaced by `mixed`;
    resumed (a run holding this mix is kept)."""
    link_copy(source, target)
    dataset = Dataset.open(target)
    for entry in tqdm(dataset.entries(), desc=f"mix {band} {split:g} m", unit="run", disable=not progress):
        run = dataset.read_run(entry, images=False)
        if run.camera is None:
            raise ConfigError(f"{dataset.path(entry)}: no camera labels to mix (label {source} first)")
        if run.camera.labeller == NAME:
            continue
        digest = hashlib.sha256(f"{run.camera.fingerprint} {band} {split!r}".encode()).hexdigest()
        labels = CameraLabels(mixed(run.bins, run.camera.bins, band, split), NAME, digest)
        dataset.set_camera_labels(entry, labels)
    return dataset


def run(out: Path, band: str, split: float = 1.0, seeds: tuple[int, ...] = (0,), runs: int = 500,
        training: tuple[tuple[str, Any], ...] = (), workers: int = 1, device: str = "auto",
        progress: bool = True) -> str:
    """The mix of `band` at `split` m, its Depth-Q-Nets of `runs` for `seeds` (the camera-label nets'
    training, `training` on top), driven in OUT's canyons; returns the rows (per seed: m to the first
    collision, ends reached, collisions)."""
    if band not in BANDS:
        raise ConfigError(f"--band must be one of {list(BANDS)}, got {band!r}")
    if not 0 < split < np.inf:
        raise ConfigError(f"--split must be a distance > 0 m, got {split!r}")
    out = Path(out).resolve()
    setup = read_setup(out)
    folder = out / "bands" / f"{band}_{split:g}"
    write_mix(out / "floor" / "data", folder / "data", band, split, progress)
    rows = ["| mix | seed | to first collision (m) | ends reached | collisions |", "|---|---|---|---|---|"]
    distances = []
    for seed in seeds:
        config, _ = camera_config(setup, folder / "data", runs, seed, training)
        name = model_name("depth", runs, seed)
        train(config, folder / "models" / name, progress=progress, device=device)
        evaluate_once(folder / "models" / name, folder / "eval" / name, setup, workers, device, progress)
        summary = read_json(folder / "eval" / name / SUMMARY)["summary"]
        distances.append(summary["distance_to_collision_mean"])
        where = (f"under {split:g} m, camera beyond" if band == "near"
                 else f"from {split:g} m on, camera nearer")
        rows.append(f"| LiDAR {where} | {seed} | "
                    f"{summary['distance_to_collision_mean']:.2f} | {summary['reached_end']} | "
                    f"{summary['collisions']} |")
    if len(seeds) > 1:
        rows.append(f"| mean | {','.join(map(str, seeds))} | {mean_interval(distances, '.2f')} | | |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    go = actions.add_parser("run", help="mix, train, drive (resumed)")
    go.add_argument("out", type=Path, help="a camera_labels experiment folder (with floor labels)")
    go.add_argument("--band", required=True, choices=BANDS,
                    help="where the LiDAR's bins replace the camera's: near (under --split) or far")
    go.add_argument("--split", type=float, default=1.0, help="the bands' border, m (default: 1.0)")
    go.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1 (default: 0)")
    go.add_argument("--runs", type=int, default=500, help="training runs (default: 500)")
    go.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a training setting over the camera-label nets' (e.g. epochs=20); repeatable")
    go.add_argument("--workers", type=int, default=1, help="processes per evaluation (default: 1)")
    go.add_argument("--device", default="auto", help="torch device (default: auto)")
    go.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)

    def work() -> int:
        print(run(args.out, args.band, args.split, parse_ints(args.seeds, "--seeds"), args.runs,
                  parse_settings(args.set, "--set"), args.workers, args.device, not args.no_progress))
        return 0

    return guarded(f"{PROG} {args.action}", work)


if __name__ == "__main__":
    sys.exit(main())
