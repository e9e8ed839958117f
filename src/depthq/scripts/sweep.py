"""Sweep a grid: networks × sizes × seeds × training settings, with tables (95 % intervals) and report."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from depthq.nets.device import DEVICE_HELP
from depthq.parallel import add_executor_arguments, executor_from


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--preset", default="quick", help="the sweep to start from: smoke, quick, paper, nominal, hard"
    )
    p.add_argument("--family", help="canyon family of the dataset: paper or hard (default: the preset's)")
    p.add_argument(
        "--canyons",
        help="evaluation canyons, e.g. hard/val:1000-1019 to compare settings on val canyons "
        "(default: the family's eval canyons)",
    )
    p.add_argument("--hz", type=float, help="decisions (camera frames) per second (default: the preset's)")
    p.add_argument("--seeds", help="training seeds, e.g. 0-9 or 0,3,7 (default: the preset's)")
    p.add_argument("--sizes", help="training-set sizes in runs, e.g. 50,200 (default: the preset's)")
    p.add_argument(
        "--runs",
        type=int,
        help="training runs to collect, at least the largest size (default: the preset's); a run's data "
        "does not depend on how many are collected, so --runs 500 --sizes 200,500 trains the models the "
        "preset's 900 runs would",
    )
    p.add_argument("--nets", help="depth, coll or depth,coll (default: both)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=V1,V2",
        help="a training setting and the values to try, e.g. dropout=0,0.5 (repeatable: their product)",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder (resumed or widened when rerun)")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    add_executor_arguments(p)


def run(args: argparse.Namespace) -> int:
    # MuJoCo and torch (report.sweep reads sim.world's decision rate): when this verb runs.
    from depthq.report.presets import get_preset
    from depthq.report.reproduce import run_sweep
    from depthq.report.sweep import parse_ints, parse_setting, retarget

    base = get_preset(args.preset)
    changes = {
        "seeds": parse_ints(args.seeds, "--seeds") if args.seeds else None,
        "subsets": parse_ints(args.sizes, "--sizes") if args.sizes else None,
        "runs": args.runs,
        "nets": tuple(args.nets.split(",")) if args.nets else None,
        "grid": tuple(parse_setting(text) for text in args.set) or None,
    }
    changes = {k: v for k, v in changes.items() if v is not None}
    target = retarget(base, args.family, args.canyons, args.hz)
    widened = bool(changes) or target != base
    sweep = replace(target, name=f"{base.name} sweep" if widened else base.name, **changes)
    times = run_sweep(sweep, args.out, device=args.device, executor=executor_from(args))
    models = len({m.name for m in sweep.models()})
    print(f"{sweep.name}: {models} models, {sum(times.values()) / 60:.1f} min of stage time in all; "
          f"tables and report in {args.out}")
    return 0
