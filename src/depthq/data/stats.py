"""The paper's Table II for a dataset: runs and samples of every nested subset, from the manifest alone;
and, where runs hold camera labels beside a LiDAR, the labels' error against it (from the run files)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from depthq.configio import to_dict
from depthq.data import DataConfig
from depthq.data.manifest import Dataset, RunEntry
from depthq.data.run import SPLITS
from depthq.data.samples import coll_sample_indices, depth_sample_indices, ends_in_collision, usable
from depthq.data.subsets import usable_runs

# LiDAR distance bands (m) of the camera labels' error; the last one holds the clip (2 m: nothing near).
ERROR_BANDS = ((0.0, 0.5), (0.5, 1.0), (1.0, 2.0))

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
                    r.n_frames, ends_in_collision(r, config.every_run_end), config.horizon, config.action_lag
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
    collected = {split: [e for e in dataset.entries(split) if e.rendered is None] for split in SPLITS}
    rendered = {split: len(dataset.entries(split)) - len(collected[split]) for split in SPLITS}
    looks = sorted({f"{e.rendered.look}:{e.rendered.seed}" for e in entries if e.rendered is not None})
    return {
        "dataset": str(dataset.root),
        "data_config": to_dict(config),
        "collected": {split: len(collected[split]) for split in SPLITS},
        "usable": {split: sum(usable(e, config.min_frames) for e in collected[split]) for split in SPLITS},
        # runs rendered again in other looks (`depthq dataset rerender`); the table counts collected runs
        **({"rendered": rendered, "rendered_looks": looks} if looks else {}),
        "frames": frames,
        "kb_per_frame": sum(e.bytes for e in entries) / 1000 / frames if frames else 0.0,
        "table": [to_dict(row) for row in rows],
    }


def label_error(dataset: Dataset) -> dict[str, Any] | None:
    """The camera labels' absolute error (m) against the LiDAR's bins, per split: per bin (left to right),
    per LiDAR distance band (ERROR_BANDS), and of each frame's nearest bin (the one that decides);
    only bins both measured and estimated count (a recording without a LiDAR has none). None when no
    run holds camera labels."""
    labellers, out = set(), {}
    for split in SPLITS:
        pairs = []
        for entry in dataset.entries(split):
            run = dataset.read_run(entry, images=False)
            if run.camera is not None:
                labellers.add((run.camera.labeller, run.camera.fingerprint))
                pairs.append((run.bins, run.camera.bins))
        if pairs:
            lidar, camera = (np.concatenate([p[i] for p in pairs]) for i in (0, 1))
            out[split] = label_errors(lidar, camera, len(pairs))
    if not labellers:
        return None
    return {"labellers": [{"name": n, "fingerprint": f} for n, f in sorted(labellers)], "splits": out}


def label_errors(lidar: np.ndarray, camera: np.ndarray, runs: int) -> dict[str, Any]:
    """Camera bins against LiDAR bins (frames, bins), of `runs` runs: per band, nearest bin, per bin."""
    valid = np.isfinite(lidar) & np.isfinite(camera)
    error = np.where(valid, np.abs(camera - lidar), np.nan)
    bands = []
    for low, high in ERROR_BANDS:
        inside = valid & (lidar >= low) & ((lidar < high) if high < ERROR_BANDS[-1][1] else (lidar <= high))
        bands.append({"band": f"{low:g}–{high:g}", "bins": int(inside.sum()), **_summary(error[inside])})
    frames = valid.any(axis=1)  # frames with a measured and estimated bin: their nearest ones
    nearest = np.abs(np.nanmin(np.where(valid, camera, np.nan)[frames], axis=1)
                     - np.nanmin(np.where(valid, lidar, np.nan)[frames], axis=1))
    with np.errstate(invalid="ignore"):
        per_bin = np.nanmean(error, axis=0) if valid.any() else np.full(lidar.shape[1], np.nan)
    return {"runs": runs, "frames": int(frames.sum()), "per_bin": [round(float(e), 4) for e in per_bin],
            "bands": bands, "nearest": _summary(nearest)}


def _summary(errors: np.ndarray) -> dict[str, float | None]:
    """Median and mean of absolute errors (None for none)."""
    if not len(errors):
        return {"median": None, "mean": None}
    return {"median": round(float(np.median(errors)), 4), "mean": round(float(np.mean(errors)), 4)}


def format_stats(stats: dict[str, Any]) -> str:
    """Table II as text, with the counts it is based on."""
    collected, usable_counts = stats["collected"], stats["usable"]
    cfg = stats["data_config"]
    lines = [
        f"{stats['dataset']}: "
        + ", ".join(f"{collected[s]} {s} runs ({usable_counts[s]} usable)" for s in SPLITS)
        + (f"; {sum(stats['rendered'].values())} runs rendered again in {len(stats['rendered_looks'])} "
           f"look(s) ({', '.join(stats['rendered_looks'])}), trained on with their sources"
           if "rendered" in stats else "")
        + f"; {stats['frames']} frames, {stats['kb_per_frame']:.1f} KB per frame stored",
        f"usable = at least {cfg['min_frames']} frames; "
        f"collision targets on the last {cfg['horizon']} samples of "
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


def error_cell(summary: dict[str, float | None], missing: str = "–") -> str:
    """An absolute error's 'median [mean]' (m) of `label_errors`; `missing` where it has no frame."""
    return missing if summary["median"] is None else f"{summary['median']:.3f} [{summary['mean']:.3f}]"


def format_label_error(report: dict[str, Any]) -> list[str]:
    """`label_error` as text lines: median [mean] absolute error in metres ('—' for none)."""
    who = ", ".join(f"{lab['name']} {lab['fingerprint'][:12]}…" for lab in report["labellers"])
    first = next(iter(report["splits"].values()))
    bands = [b["band"] for b in first["bands"]]
    lines = [
        f"camera labels ({who}) against the LiDAR: absolute error, median [mean] m",
        f"{'split':>6} {'runs':>5} {'frames':>7} {'nearest bin':>14} "
        + " ".join(f"{band + ' m':>14}" for band in bands),
    ]
    for split, row in report["splits"].items():
        lines.append(f"{split:>6} {row['runs']:>5} {row['frames']:>7} {error_cell(row['nearest'], '—'):>14} "
                     + " ".join(f"{error_cell(b, '—'):>14}" for b in row["bands"]))
    for split, row in report["splits"].items():
        lines.append(f"{split:>6} per bin, left to right (mean): "
                     + " ".join(f"{e:.2f}" for e in row["per_bin"]))
    return lines


def stats_report(dataset: Dataset, config: DataConfig) -> tuple[dict[str, Any], str]:
    """What `depthq dataset stats` prints: the record of `--json` (the subsets' statistics, and the
    camera labels' error where runs hold them) and the text."""
    stats, labels = dataset_stats(dataset, config), label_error(dataset)
    record = {**stats, **({"camera_labels": labels} if labels else {})}
    text = "\n".join([format_stats(stats), *(["", *format_label_error(labels)] if labels else [])])
    return record, text
