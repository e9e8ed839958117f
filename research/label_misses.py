"""Where camera labels go wrong near obstacles (issue #32): each near bin's error, split by what the
LiDAR's nearest reading in it hits (a pillar or a wall) and by how the estimate errs.

A floor labeller (docs/design.md#camera-labels) reads no obstacle nearer than its `nearest` m (the
rows below are never searched), so an obstacle there reads at least that far: a bounded error by
construction. An obstacle it takes for floor reads as whatever lies behind it: an unbounded one. This
tells the two apart on a labelled dataset's runs, in the canyons they were collected in.

    python -m research.label_misses DATA [--split val] [--near 0.5] [--json OUT.json]

DATA is a dataset with camera labels (`depthq label DATA --from camera`) collected in simulated
canyons (a robot's recording has none to re-simulate).

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/research/camera_labels.md came from the code of commit 98b6acc
(2026-11-26: the last change of those tables).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from depthq.configio import write_json
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError, guarded
from depthq.labellers.labeller import LabellerConfig, bin_geometry
from depthq.sim.canyon import FAMILIES, CanyonId, generate_canyon
from depthq.sim.mjcf import RobotConfig
from depthq.sim.sensors import BinConfig
from research.truth import canyon

PROG = "python -m research.label_misses"
KINDS = ("pillar", "wall")
PILLAR_MARGIN = 0.05  # m beyond a pillar's radius that a hit still counts as the pillar's (range noise)
# m: the floor labeller's default nearest reading (no obstacle is searched nearer)
NEAREST = LabellerConfig.__dataclass_fields__["nearest"].default
MISSED = 0.3  # m: an estimate farther than the truth by more than this took the obstacle for floor


def nearest_hits(scan: np.ndarray, pose: np.ndarray, bins: BinConfig, offset_x: float) -> np.ndarray:
    """(n_bins, 2) world points of each bin's nearest valid reading (NaN where it has none)."""
    bearings = (bins.first_bearing - np.arange(bins.n_readings)) % scan.shape[-1]
    readings = scan[bearings].astype(np.float64).reshape(bins.n_bins, bins.group)
    readings = np.where(np.isfinite(readings) & (readings > 0), readings, np.inf)
    pick = readings.argmin(axis=1)
    distance = readings[np.arange(bins.n_bins), pick]
    angle = pose[2] + np.deg2rad(bearings.reshape(bins.n_bins, bins.group)[np.arange(bins.n_bins), pick])
    x0 = pose[0] + offset_x * np.cos(pose[2])
    y0 = pose[1] + offset_x * np.sin(pose[2])
    hits = np.stack([x0 + distance * np.cos(angle), y0 + distance * np.sin(angle)], axis=1)
    return np.where(np.isfinite(distance)[:, None], hits, np.nan)


def is_pillar(hits: np.ndarray, obstacles: np.ndarray) -> np.ndarray:
    """Whether each hit point (…, 2) lies on one of the canyon's pillars (k, 3: x, y, radius)."""
    if not len(obstacles):
        return np.zeros(hits.shape[:-1], bool)
    gap = np.linalg.norm(hits[..., None, :] - obstacles[:, :2], axis=-1) - obstacles[:, 2]
    return (gap < PILLAR_MARGIN).any(axis=-1)


def measure(dataset: Dataset, split: str = "val", near: float = 0.5, far: float = 0.0) -> dict[str, Any]:
    """Per kind of obstacle, the bins whose LiDAR reading is in [`far`, `near`) m (both bins valid):
    their count, the absolute error's median and mean, and the shares under-estimated, within `MISSED`
    m, and missed."""
    family = dataset.family()
    if family is None:
        raise ConfigError(f"{dataset.root}: a robot's recording has no canyons to tell pillars from walls")
    config = FAMILIES[family].canyon
    bins = BinConfig(**bin_geometry(dataset))
    offset_x = RobotConfig().sensor_offset_x
    errors: dict[str, list[np.ndarray]] = {kind: [] for kind in KINDS}
    truths: dict[str, list[np.ndarray]] = {kind: [] for kind in KINDS}
    labelled = 0
    for entry in dataset.entries(split):
        run = dataset.read_run(entry, images=False)
        if run.camera is None:
            continue
        labelled += 1
        obstacles = generate_canyon(CanyonId.parse(canyon(dataset, split, run.meta.index)), config).obstacles
        valid = np.isfinite(run.bins) & np.isfinite(run.camera.bins)
        near_bins = valid & (run.bins < near) & (run.bins >= far)
        for t in np.flatnonzero(near_bins.any(axis=1)):
            pillar = is_pillar(nearest_hits(run.scans[t], run.poses[t].astype(np.float64), bins, offset_x),
                               obstacles)
            for kind, mask in (("pillar", pillar), ("wall", ~pillar)):
                chosen = near_bins[t] & mask
                errors[kind].append(run.camera.bins[t, chosen] - run.bins[t, chosen])
                truths[kind].append(run.bins[t, chosen])
    if not labelled:
        raise ConfigError(f"{dataset.root}: no {split} run holds camera labels (`depthq label` first)")
    out: dict[str, Any] = {"data": str(dataset.root), "split": split, "near": near, "far": far,
                           "runs": labelled, "missed_above": MISSED, "kinds": {}}
    for kind in KINDS:
        err = np.concatenate(errors[kind]) if errors[kind] else np.empty(0)
        truth = np.concatenate(truths[kind]) if truths[kind] else np.empty(0)
        n = len(err)
        share = (lambda m: round(float(m.mean()), 4)) if n else (lambda m: None)
        out["kinds"][kind] = {
            "bins": n,
            "median_abs": round(float(np.median(np.abs(err))), 4) if n else None,
            "mean_abs": round(float(np.abs(err).mean()), 4) if n else None,
            "under": share(err < -MISSED),  # read nearer than it is
            "within": share(np.abs(err) <= MISSED),
            "missed": share(err > MISSED),  # read farther: taken for floor
            "truth_below_nearest": share(truth < NEAREST),
            "missed_error_mean": round(float(err[err > MISSED].mean()), 4) if (err > MISSED).any() else None,
        }
    return out


def table(result: dict[str, Any]) -> str:
    """The Markdown table of `measure`'s result."""
    lines = [f"Bins with a LiDAR reading in [{result['far']:g}, {result['near']:g}) m of {result['runs']} "
             f"{result['split']} runs of {result['data']}; missed = estimate farther than the truth by > "
             f"{result['missed_above']:g} m", "",
             "| hit | bins | error median [mean] (m) | within | missed | read nearer "
             f"| truth < {NEAREST:g} m | missed: mean error (m) |", "|---|---|---|---|---|---|---|---|"]

    def pct(value: float | None) -> str:
        return "–" if value is None else f"{100 * value:.0f} %"

    for kind, r in result["kinds"].items():
        error = "–" if r["median_abs"] is None else f"{r['median_abs']:.3f} [{r['mean_abs']:.3f}]"
        missed = "–" if r["missed_error_mean"] is None else f"{r['missed_error_mean']:.2f}"
        lines.append(f"| {kind} | {r['bins']} | {error} | {pct(r['within'])} | {pct(r['missed'])} | "
                     f"{pct(r['under'])} | {pct(r['truth_below_nearest'])} | {missed} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    parser.add_argument("data", type=Path, help="a dataset with camera labels, collected in simulation")
    parser.add_argument("--split", default="val", choices=("train", "val"),
                        help="runs to measure (default: val)")
    parser.add_argument("--near", type=float, default=0.5, help="bins whose LiDAR reading is nearer than "
                                                                 "this count, m (default: 0.5)")
    parser.add_argument("--far", type=float, default=0.0, help="... and not nearer than this, m (default: 0)")
    parser.add_argument("--json", type=Path, default=None, help="also write the result as JSON here")
    args = parser.parse_args(argv)

    def work() -> int:
        if not 0 <= args.far < args.near:
            raise ConfigError(f"--far and --near must satisfy 0 <= far < near, got {args.far}, {args.near}")
        result = measure(Dataset.open(args.data), args.split, args.near, args.far)
        if args.json:
            write_json(args.json, result)
        print(table(result))
        return 0

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
