"""How long a camera labeller should remember (issue #32): a dataset's runs labelled by one floor or
monodepth labeller at several memory lengths (`LabellerConfig.memory_s`), each rated against the LiDAR
as `depthq dataset stats` rates labels (nearest bin, distance bands). Choose on `val` runs.

    python -m research.label_memory LABELLER DATA [--memory 0,0.5,1,2,4] [--split val]

LABELLER is a floor or monodepth labeller folder (`depthq labeller --method floor|monodepth`); DATA a
simulated dataset of its camera (its LiDAR is the truth here; nothing is written into it). Each frame's
own readings are computed once; only the memory differs between the rows.

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
from tqdm import tqdm

from depthq.configio import write_json
from depthq.data.manifest import Dataset
from depthq.data.stats import label_errors
from depthq.errors import ConfigError, guarded
from depthq.labellers import floor
from depthq.labellers.labeller import check_applicable, load_labeller

PROG = "python -m research.label_memory"


def measure(labeller: Path, dataset: Dataset, memories: tuple[float, ...], split: str = "val",
            progress: bool = True) -> dict[str, Any]:
    """Per memory length (s), `label_errors` of the labeller's bins against the LiDAR's on `split`."""
    loaded = load_labeller(labeller)
    estimate = loaded.estimate
    if not isinstance(estimate, floor.ReadingsEstimate):
        raise ConfigError(f"{labeller}: a {loaded.record['name']} labeller has no memory (a floor or "
                          "monodepth one has)")
    check_applicable(loaded, dataset)
    if any(not 0 <= m < np.inf for m in memories):
        raise ConfigError(f"--memory: lengths must be finite seconds >= 0, got {list(memories)}")
    entries = dataset.entries(split)
    if not entries:
        raise ConfigError(f"{dataset.root}: no {split} runs")
    lidar, camera = [], {m: [] for m in memories}
    for entry in tqdm(entries, desc=f"label {split}", unit="run", disable=not progress):
        run = dataset.read_run(entry, images=True)
        readings = estimate.readings(run.images)
        lidar.append(run.bins)
        for m in memories:
            camera[m].append(estimate.bins(readings, run, m))
    truth = np.concatenate(lidar)
    rows = {str(m): label_errors(truth, np.concatenate(camera[m]), len(entries)) for m in memories}
    return {"labeller": str(labeller), "data": str(dataset.root), "split": split, "memory_s": rows}


def table(result: dict[str, Any]) -> str:
    """The Markdown table of `measure`'s result: median [mean] absolute error, m."""
    def cell(summary: dict[str, float | None]) -> str:
        return "–" if summary["median"] is None else f"{summary['median']:.3f} [{summary['mean']:.3f}]"

    first = next(iter(result["memory_s"].values()))
    bands = [b["band"] for b in first["bands"]]
    lines = [f"{result['labeller']} on the {result['split']} runs of {result['data']} ({first['frames']} "
             "frames): absolute error against the LiDAR, median [mean] m", "",
             "| memory (s) | nearest bin | " + " | ".join(f"{b} m" for b in bands) + " |",
             "|---" * (len(bands) + 2) + "|"]
    for memory, row in result["memory_s"].items():
        lines.append(f"| {memory} | {cell(row['nearest'])} | "
                     + " | ".join(cell(b) for b in row["bands"]) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    parser.add_argument("labeller", type=Path,
                        help="a floor or monodepth labeller folder (`depthq labeller`)")
    parser.add_argument("data", type=Path, help="a simulated dataset of the labeller's camera")
    parser.add_argument("--memory", default="0,0.5,1,2,4",
                        help="memory lengths to compare, s, comma-separated (default: 0,0.5,1,2,4)")
    parser.add_argument("--split", default="val", choices=("train", "val"),
                        help="runs to rate (default: val)")
    parser.add_argument("--json", type=Path, default=None, help="also write the result as JSON here")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)

    def work() -> int:
        try:
            memories = tuple(float(m) for m in args.memory.split(","))
        except ValueError:
            raise ConfigError(f"--memory must be seconds separated by commas, got {args.memory!r}") from None
        result = measure(args.labeller, Dataset.open(args.data), memories, args.split, not args.no_progress)
        if args.json:
            write_json(args.json, result)
        print(table(result))
        return 0

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
