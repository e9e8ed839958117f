"""Train a Depth-Q-Net or Coll-Q-Net on a collected dataset (resumes an interrupted training)."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.nets.device import DEVICE_HELP
from depthq.nets.trunk import DEFAULT_TRUNK
from depthq.train.config import DEFAULT_EPOCHS


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", required=True, help="depth (Depth-Q-Net) or coll (Coll-Q-Net)")
    p.add_argument("--data", type=Path, required=True, help="dataset folder (depthq collect --out)")
    p.add_argument("--runs", type=int, default=None, help="train on the first N usable runs (default: all)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="checkpoint folder (created, or resumed)")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    p.add_argument("--epochs", type=int, default=DEFAULT_EPOCHS,
                   help=f"epochs of 100 training + 10 validation batches (default {DEFAULT_EPOCHS})")
    p.add_argument("--trunk", default=DEFAULT_TRUNK,
                   help=f"{DEFAULT_TRUNK} (frozen, default), efficientnet_lite0 (frozen, globally pooled) "
                   "efficientnet_lite0_columns_tuned (fine-tuned with the head) or mobilenet_v1_025 "
                   "(from scratch)")
    p.add_argument("--lr", type=float, default=None,
                   help="learning rate (default 0.1; the paper: 0.1 depth, 0.01 coll)")
    p.add_argument("--dropout", type=float, default=0.0,
                   help="dropout on the feature (paper: 0.5; see TrainConfig)")
    p.add_argument("--depth-loss", default="original",
                   help="original (the authors' L1, averaged over all bins) or valid_mean")
    p.add_argument("--action-lag", type=int, default=0,
                   help="1: label frame t with the command of frame t-1 (the original recorder, likely)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from depthq.configio import read_json
    from depthq.train.config import TrainConfig
    from depthq.train.trainer import train

    config = TrainConfig(model=args.model, data=str(args.data), runs=args.runs, seed=args.seed,
                         epochs=args.epochs, trunk=args.trunk, lr=args.lr, dropout=args.dropout,
                         depth_loss=args.depth_loss, action_lag=args.action_lag)
    out = train(config, args.out, progress=not args.no_progress, device=args.device)
    best, last = read_json(out / "best.json"), read_json(out / "last.json")
    print(f"checkpoint: {out} (best.safetensors: epoch {best['epoch']}, "
          f"last.safetensors: epoch {last['epoch']})")
    for name, row in (("best", best), ("last", last)):
        print(f"{name}: train_loss {row['train_loss']:.4f}  val_loss {row['val_loss']:.4f}  "
              f"val_loss_std {row['val_loss_std']:.4f}")
    return 0
