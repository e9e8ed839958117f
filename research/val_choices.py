"""The design choices of issue #10, measured on validation data and `val` canyons only (docs/val_choices.md).

    python -m research.val_choices runs/paper/data runs/val-choices [variant ...]

Trains each variant (a Depth-Q-Net or Coll-Q-Net on the first n runs of the dataset, seed 0, with
some TrainConfig fields changed) and drives it in the 20 canyons val:1000-1019, which no dataset
and no evaluation table uses. Prints (and writes to OUT/val_choices.md) one row per variant:
validation loss, successes, mean distance, how runs ended. Finished variants are reused.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/val_choices.md came from the code of commit 5a1fe2f (2026-11-23: the last change of that page's
tables).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from depthq.checkpoint import epoch_seconds, read_sidecar
from depthq.configio import read_json
from depthq.data.samples import SampleConfig
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.train.config import TrainConfig
from depthq.train.trainer import train

CANYONS = "val:1000-1019"
POOLED = "efficientnet_lite0"  # the trunk's feature before the columns became the default
# Each choice against its alternative, in the order they were made; "action_scale" 1 is the head as
# it was before #10.
VARIANTS: dict[str, dict] = {
    "depth_n200": {"model": "depth", "runs": 200, "action_scale": 1.0, "trunk": POOLED},
    "depth_n200_action10": {"model": "depth", "runs": 200, "action_scale": 10.0, "trunk": POOLED},
    "depth_n200_action10_lag1": {
        "model": "depth", "runs": 200, "action_scale": 10.0, "samples": SampleConfig(action_lag=1),
        "trunk": POOLED,
    },
    # the paper's rate
    "coll_n500_lr0.01": {"model": "coll", "runs": 500, "action_scale": 1.0, "lr": 0.01, "trunk": POOLED},
    "coll_n500_lr0.1": {"model": "coll", "runs": 500, "action_scale": 1.0, "lr": 0.1, "trunk": POOLED},
    "coll_n500_lr0.1_action10": {
        "model": "coll", "runs": 500, "action_scale": 10.0, "lr": 0.1, "trunk": POOLED
    },
    # The trunk's feature: 320 channels × 4 image columns instead of the global pool (same size).
    "depth_n200_columns": {"model": "depth", "runs": 200, "trunk": "efficientnet_lite0_columns"},
    "coll_n500_columns": {"model": "coll", "runs": 500, "trunk": "efficientnet_lite0_columns"},
    # Why Coll-Q-Net is strong here: the two networks side by side on the column feature, and
    # Coll-Q-Net with the paper's own rate and raw action (measurements, not choices).
    "coll_n200_columns": {"model": "coll", "runs": 200, "trunk": "efficientnet_lite0_columns"},
    "depth_n500_columns": {"model": "depth", "runs": 500, "trunk": "efficientnet_lite0_columns"},
    "coll_n500_columns_paper": {
        "model": "coll", "runs": 500, "trunk": "efficientnet_lite0_columns", "lr": 0.01, "action_scale": 1.0
    },
    "depth_n500_columns_action1": {
        "model": "depth", "runs": 500, "trunk": "efficientnet_lite0_columns", "action_scale": 1.0
    },
    # The paper's trunk trained with the head (from scratch: no MobileNet weights offline), which a
    # frozen ImageNet feature cannot be: can 26 dense depth targets per frame teach it what a class
    # label cannot (the distance of a texture-less wall)? 100 epochs, 2.5× the frozen budget (the
    # paper ran up to 1000); a GPU job (fourth #10 session).
    **{
        f"{model}_n{runs}_mobilenet": {
            "model": model, "runs": runs, "trunk": "mobilenet_v1_025", "epochs": 100
        }
        for runs in (200, 500)
        for model in ("depth", "coll")
    },
    # The column feature's network fine-tuned with the head from its ImageNet weights (40 epochs).
    **{
        f"{model}_n{runs}_columns_tuned": {
            "model": model, "runs": runs, "trunk": "efficientnet_lite0_columns_tuned"
        }
        for runs in (200, 500)
        for model in ("depth", "coll")
    },
}



def run_variant(
    data: Path,
    out: Path,
    name: str,
    variants: dict[str, dict] = VARIANTS,
    eval_config: EvalConfig | None = None,
) -> dict[str, Any]:
    """Train variant `name` into OUT/NAME (resumed) and drive it in CANYONS (by default) into
    OUT/eval/NAME, unless that evaluation exists; its table row."""
    ckpt, ev = out / name, out / "eval" / name
    train(TrainConfig(data=str(data), **variants[name]), ckpt, progress=False)
    summary_path = ev / "summary.json"
    if summary_path.is_file():
        result = read_json(summary_path)
    else:
        config = eval_config or EvalConfig(canyons=parse_canyon_set(CANYONS))
        result = evaluate(str(ckpt), ev, config, progress=False, video=False)
    s = result["summary"]
    best, last = read_sidecar(ckpt, "best"), read_sidecar(ckpt, "last")
    took = epoch_seconds(ckpt).get(last["epoch"], float("nan"))
    print(f"{name}: best epoch {best['epoch']} of {last['epoch']}, {took:.1f} s/epoch", flush=True)
    return {
        "variant": name,
        "val_loss": best["val_loss"],
        "successes": s["successes"],
        "distance": round(s["distance_mean"], 2),
        "imitation": round(s["imitation_loss_mean"], 3),
        "ends": dict(Counter(r["end_reason"] for r in result["runs"])),
    }


def table(rows: list[dict[str, Any]]) -> str:
    """Markdown: one row per variant."""
    lines = [
        "| variant | best val loss | successes / 20 | distance (m) | imitation | ends |",
        "|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['variant']} | {r['val_loss']:.4f} | {r['successes']} | {r['distance']} | {r['imitation']} | "
        f"{json.dumps(r['ends'])} |"
        for r in rows
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.val_choices",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("data", type=Path, help="the dataset folder the variants train on")
    parser.add_argument("out", type=Path,
                        help="the folder for the checkpoints, evaluations and val_choices.md")
    parser.add_argument("variants", nargs="*", metavar="variant",
                        help=f"variants to run (default: all): {', '.join(VARIANTS)}")
    args = parser.parse_args(argv)
    if unknown := sorted(set(args.variants) - set(VARIANTS)):
        parser.error(f"unknown variant(s) {unknown}")
    rows = [run_variant(args.data, args.out, name) for name in args.variants or list(VARIANTS)]
    text = table(rows)
    print(text)
    (args.out / "val_choices.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
