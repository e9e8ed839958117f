"""Reproduce the paper's Table I, Table II, Fig. 4 and Fig. 5 with one command (resumable)."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.blocks.device import DEVICE_HELP
from depthq.parallel import add_executor_arguments, executor_from
from depthq.pipeline.preset_times import DEFAULT_PRESET, DURATIONS, presets_help
from depthq.scripts.sweep import DRY_RUN_HELP


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default=DEFAULT_PRESET, metavar="{" + ",".join(DURATIONS) + "}",
                   help=presets_help())
    p.add_argument("--out", type=Path, required=True, help="output folder (resumed when run again)")
    p.add_argument("--dry-run", action="store_true", help=DRY_RUN_HELP)
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    add_executor_arguments(p)


def run(args: argparse.Namespace) -> int:
    from depthq.pipeline.plan import plan  # MuJoCo and torch: when this verb runs
    from depthq.pipeline.presets import get_preset
    from depthq.report.reproduce import reproduce

    if args.dry_run:
        print(plan(get_preset(args.preset), args.out, args.device))
        return 0
    times = reproduce(args.preset, args.out, device=args.device, executor=executor_from(args))
    total = sum(times.values())
    print("\n".join(f"{k:>40}: {v:8.1f} s" for k, v in times.items()))
    print(f"preset {args.preset}: {total / 60:.1f} min of stage time; report at {args.out / 'report.html'}")
    return 0
