"""Export a trained Q-net as one ONNX graph (frame in, per-action values out) for a robot."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.errors import ConfigError


def _frame_size(text: str) -> tuple[int, int]:
    try:
        height, width = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ConfigError(f"--frame-size must be HEIGHTxWIDTH, e.g. 308x410; got {text!r}") from None
    return height, width


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoint", type=Path, help="a checkpoint folder written by `depthq train`")
    p.add_argument("--out", type=Path, required=True, help="folder for <checkpoint name>.onnx")
    p.add_argument("--weights", "--which", dest="weights", default=None,
                   help="best (lowest validation loss), last (= final), average or epoch:N [the checkpoint's "
                   "own, train --weights]; --which: its old name")
    p.add_argument("--frame-size", default=None,
                   help="camera frame the graph takes, HEIGHTxWIDTH [the checkpoint's: its data's frames]")


def run(args: argparse.Namespace) -> int:
    from depthq.deploy.onnx_export import export_onnx  # torch: when this verb runs

    frame_size = None if args.frame_size is None else _frame_size(args.frame_size)
    path = export_onnx(args.checkpoint, args.out, weights=args.weights, frame_size=frame_size)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB); drive it with the policy onnx:{path}")
    return 0
