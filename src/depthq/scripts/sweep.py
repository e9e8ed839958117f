"""Sweep a grid: networks × sizes × seeds × training settings, with tables (95 % intervals) and report."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.blocks.device import DEVICE_HELP
from depthq.flags import add_config_arguments
from depthq.networks import network_names
from depthq.parallel import add_executor_arguments, executor_from

DRY_RUN_HELP = ("print the models, their settings and each stage's command (done ones marked), "
                "and write nothing")

# The dataset's settings a sweep may change (its collection config, `Sweep.collect`), by their flags of
# `depthq collect` (--hz and --family as collect spells them too); each defaults to the preset's.
_COLLECT = ("runs", "env.world.decision_hz", "env.world.family", "env.world.look")
_ALIASES = {"env.world.decision_hz": ("--hz",), "env.world.family": ("--family",),
            "env.world.look": ("--look",)}
_HELP = {
    "runs": "at least the largest size; a run's data does not depend on how many are collected, so --runs "
    "500 --sizes 200,500 trains the models the preset's 900 runs would",
    "env.world.decision_hz": "the evaluations' rate too",
    "env.world.family": "the evaluation canyons become the family's eval canyons",
    "env.world.look": "the evaluations' look too",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    from depthq.data.recorder import CollectConfig  # MuJoCo: only when this verb's flags are built
    from depthq.pipeline.presets import PRESETS

    p.add_argument("--preset", default="quick", metavar="{" + ",".join(PRESETS) + "}",
                   help="the sweep to start from (default: quick)")
    p.add_argument(
        "--canyons",
        help="evaluation canyons, e.g. hard/val:1000-1019 to compare settings on val canyons "
        "(default: the family's eval canyons)",
    )
    p.add_argument("--seeds", help="training seeds, e.g. 0-9 or 0,3,7 (default: the preset's)")
    p.add_argument("--sizes", help="training-set sizes in runs, e.g. 50,200 (default: the preset's)")
    nets = ",".join(network_names())
    p.add_argument("--nets", help=f"networks, comma-separated: some of {nets} (default: every registered "
                   "network; a preset names its own, which `depthq reproduce` trains)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=V1,V2",
        help="a training setting (a TrainConfig field, as `depthq train` spells its flag) and the values "
        "to try, each as that flag takes it, e.g. dropout=0,0.5, lr=none,0.05 or samples.horizon=2,5 "
        "(repeatable: their product; a Depth-Q-Net-only setting leaves Coll-Q-Net's models as they are)",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder (resumed or widened when rerun)")
    p.add_argument("--dry-run", action="store_true", help=DRY_RUN_HELP)
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    add_executor_arguments(p)
    add_config_arguments(p, CollectConfig, only=_COLLECT, aliases=_ALIASES, more_help=_HELP,
                         shown_defaults=dict.fromkeys(_COLLECT, "the preset's"))


def run(args: argparse.Namespace) -> int:
    # MuJoCo and torch (pipeline.sweep reads sim.world's decision rate): when this verb runs.
    from depthq.pipeline.plan import plan
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.runner import run_sweep
    from depthq.pipeline.sweep import parse_ints, parse_setting, retarget, widened
    from depthq.report.build import build_report

    base = get_preset(args.preset)
    given = vars(args)
    nets = tuple(args.nets.split(",")) if args.nets else network_names()
    changes = {
        "seeds": parse_ints(args.seeds, "--seeds") if args.seeds else None,
        "subsets": parse_ints(args.sizes, "--sizes") if args.sizes else None,
        "nets": nets if nets != base.nets else None,
        "grid": tuple(parse_setting(text) for text in args.set) or None,
    }
    changes = {k: v for k, v in changes.items() if v is not None}
    target = retarget(base, given.get("env.world.family"), args.canyons, given.get("env.world.decision_hz"),
                      given.get("env.world.look"))
    runs = given.get("runs")
    widened_ = bool(changes) or runs is not None or target != base
    sweep = widened(target, runs, name=f"{base.name} sweep" if widened_ else base.name, **changes)
    if args.dry_run:
        print(plan(sweep, args.out, args.device))
        return 0
    times = run_sweep(sweep, args.out, device=args.device, executor=executor_from(args), finish=build_report)
    models = len({m.name for m in sweep.models()})
    print(f"{sweep.name}: {models} models, {sum(times.values()) / 60:.1f} min of stage time in all; "
          f"tables and report in {args.out}")
    return 0
