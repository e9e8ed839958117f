"""Evaluate a policy once in each evaluation canyon (Table I's online metrics)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from depthq.blocks.device import DEVICE_HELP
from depthq.blocks.migrations import RENAMED_EVAL_SETTINGS
from depthq.flags import add_config_arguments, config_from_args, flag_name
from depthq.parallel import add_executor_arguments, executor_from

# EvalConfig's fields keep the flags they had before they were made from it, as aliases, and
# Depth-Q-Net's acting settings the flat ones they had before they were its own (--rule for
# --depth.rule); --canyons stays a canyon set ('eval:0-4'), parsed by the verb.
_ALIASES = {"time_limit_s": ("--time-limit",), "decision_hz": ("--hz",), "weights": ("--which",),
            **{path: (flag_name(old),) for old, path in RENAMED_EVAL_SETTINGS.items()}}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("policy", help="'heuristic', 'ou', a checkpoint folder or 'onnx:PATH'")
    p.add_argument(
        "--canyons", default=None,
        help="'eval' (all 20), 'eval:0-4', 'eval:2,7', 'val:1000-1019' or a fresh stream no project code "
        "uses, 'stream7:0-19'; another canyon family in front: 'hard/eval', 'hard/val:1000-1019' "
        "(default: the eval canyons of a checkpoint's canyon family)",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    p.add_argument("--workers", type=int, default=2, help="processes, each driving its share of the canyons")
    p.add_argument("--data", type=Path, default=None,
                   help="a checkpoint's dataset for the offline metrics, if moved [where it was trained]")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON line")
    p.add_argument("--no-video", action="store_true", help="skip video.mp4 of the first canyon")
    add_executor_arguments(p)
    from depthq.evaluate.online import EvalConfig  # MuJoCo: only when this verb's flags are built

    add_config_arguments(p, EvalConfig, exclude=("canyons",), aliases=_ALIASES)


def run(args: argparse.Namespace) -> int:
    from depthq.evaluate.online import (  # MuJoCo and torch
        EvalConfig,
        default_canyons,
        evaluate,
        parse_canyon_set,
    )
    from depthq.policies.spec import PolicySpec

    spec = PolicySpec.parse(args.policy)
    canyons = parse_canyon_set(args.canyons or default_canyons(spec))
    config = config_from_args(EvalConfig, args, canyons=canyons)
    result = evaluate(
        spec, args.out, config, workers=args.workers, device=args.device, video=not args.no_video,
        executor=executor_from(args), data=args.data,
    )
    s = result["summary"]
    if args.json:
        print(json.dumps({"policy": result["policy"]["policy"], **s, "seconds": result["seconds"]}))
    else:
        print(
            f"{result['policy']['policy']}: {s['successes']}/{s['runs']} successes, distance "
            f"{s['distance_mean']:.2f} ± {s['distance_std']:.2f} m, imitation loss "
            f"{s['imitation_loss_mean']:.3f}, decision {s['decision_ms_median']:.2f} ms median; "
            f"{result['seconds']:.0f} s; files in {args.out}"
        )
    return 0
