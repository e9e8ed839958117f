"""The paper's Table II for a dataset: runs and samples of every nested subset, from the manifest alone."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from depthq.configio import to_dict
from depthq.data import DataConfig
from depthq.data.labels import coll_sample_indices, depth_sample_indices, labelled_collision, usable
from depthq.data.manifest import Dataset, RunEntry
from depthq.data.run import SPLITS
from depthq.data.subsets import usable_runs

# The paper's Table II: runs → (samples, samples without collision); ≈ 47 frames per run.
PAPER_TABLE2 = {
    50: (2214, 1858),
    100: (4258, 3945),
    200: (8854, 7797),
    500: (23361, 20517),
    700: (33303, 29152),
    900: (42424, 38032),
}


@dataclass(frozen=True)
class SubsetStats:
    """One row of Table II. `samples` is Coll-Q-Net's count, `samples_without_collision` Depth-Q-Net's."""

    subset: str
    runs: int
    samples: int
    samples_without_collision: int
    mean_run_length: float
    collision_fraction: float


def subset_stats(subset: str, runs: list[RunEntry], config: DataConfig) -> SubsetStats:
    lengths = np.array([run.n_frames for run in runs], dtype=np.float64)
    return SubsetStats(
        subset=subset,
        runs=len(runs),
        samples=sum(len(coll_sample_indices(r.n_frames, config.action_lag)) for r in runs),
        samples_without_collision=sum(
            len(
                depth_sample_indices(
                    r.n_frames, labelled_collision(r, config.every_run_end), config.horizon, config.action_lag
                )
            )
            for r in runs
        ),
        mean_run_length=float(lengths.mean()) if runs else 0.0,
        collision_fraction=float(np.mean([r.collision for r in runs])) if runs else 0.0,
    )


def dataset_stats(dataset: Dataset, config: DataConfig) -> dict[str, Any]:
    """Table II rows (each subset that fits, all usable training runs, the validation split) and totals."""
    train = usable_runs(dataset, "train", config.min_frames)
    rows = [subset_stats(str(n), train[:n], config) for n in config.subsets if n <= len(train)]
    rows.append(subset_stats("all", train, config))
    rows.append(subset_stats("val", usable_runs(dataset, "val", config.min_frames), config))
    entries = dataset.entries()
    frames = sum(e.n_frames for e in entries)
    return {
        "dataset": str(dataset.root),
        "data_config": to_dict(config),
        "collected": {split: len(dataset.entries(split)) for split in SPLITS},
        "usable": {
            split: sum(usable(e, config.min_frames) for e in dataset.entries(split)) for split in SPLITS
        },
        "frames": frames,
        "kb_per_frame": sum(e.bytes for e in entries) / 1000 / frames if frames else 0.0,
        "table": [to_dict(row) for row in rows],
    }


def format_stats(stats: dict[str, Any]) -> str:
    """Table II as text, with the counts it is based on."""
    collected, usable_counts = stats["collected"], stats["usable"]
    cfg = stats["data_config"]
    lines = [
        f"{stats['dataset']}: "
        + ", ".join(f"{collected[s]} {s} runs ({usable_counts[s]} usable)" for s in SPLITS)
        + f"; {stats['frames']} frames, {stats['kb_per_frame']:.1f} KB per frame stored",
        f"usable = at least {cfg['min_frames']} frames; "
        f"collision labels on the last {cfg['horizon']} samples of "
        + ("every run" if cfg.get("every_run_end") else "runs that ended in a bump")
        + "; paper = the paper's Table II",
        "",
        f"{'subset':>6} {'runs':>6} {'samples':>9} {'w/o collision':>14} "
        f"{'mean length':>12} {'bumped':>8} {'paper':>7} {'paper w/o':>10} {'ratio':>6}",
    ]
    for row in stats["table"]:
        paper = PAPER_TABLE2.get(int(row["subset"])) if row["subset"].isdigit() else None
        theirs = f"{paper[0]:>7} {paper[1]:>10} {row['samples'] / paper[0]:>6.2f}" if paper else ""
        lines.append(
            f"{row['subset']:>6} {row['runs']:>6} {row['samples']:>9} {row['samples_without_collision']:>14} "
            f"{row['mean_run_length']:>12.1f} {row['collision_fraction']:>8.1%} {theirs}"
        )
    return "\n".join(lines)
