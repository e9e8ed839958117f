"""Train a Depth-Q-Net or Coll-Q-Net on a collected dataset (resumes an interrupted training)."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.blocks.device import DEVICE_HELP
from depthq.blocks.migrations import RENAMED_SETTINGS
from depthq.checkpoint import chosen_weights, read_config, read_sidecar
from depthq.flags import add_config_arguments, config_from_args, flag_name
from depthq.train.config import TrainConfig

# Older spellings of TrainConfig's flags, accepted for one release: --select, and the sample settings'
# flat flags from before TrainConfig held them in `samples` (--horizon for --samples.horizon).
_ALIASES = {path: (flag_name(old),) for old, path in RENAMED_SETTINGS.items()}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, help="checkpoint folder (created, or resumed)")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_config_arguments(p, TrainConfig, aliases=_ALIASES)


def run(args: argparse.Namespace) -> int:
    from depthq.train.trainer import train  # the data views and the trainer: when this verb runs

    config = config_from_args(TrainConfig, args)  # every field from its flag (weights, snapshots, ...)
    out = train(config, args.out, progress=not args.no_progress, device=args.device)
    best, last = read_sidecar(out, "best"), read_sidecar(out, "last")
    average = read_sidecar(out, "average") if config.average else None
    also = f", average.safetensors: epochs {average['epochs'][0]}–{average['epochs'][1]}" if average else ""
    acts = chosen_weights(read_config(out), None, out)
    why = "" if acts == config.weights else f" ({config.weights} fails its check: design.md#weight-average)"
    print(f"checkpoint: {out} (best.safetensors: epoch {best['epoch']}, "
          f"last.safetensors: epoch {last['epoch']}{also}; acts with {acts}{why})")
    for name, row in (("best", best), ("last", last)):
        print(f"{name}: train_loss {row['train_loss']:.4f}  val_loss {row['val_loss']:.4f}  "
              f"val_loss_std {row['val_loss_std']:.4f}")
    return 0
