"""Evaluate a policy once in each evaluation canyon (Table I's online metrics)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from depthq.nets.device import DEVICE_HELP
from depthq.parallel import add_executor_arguments, executor_from


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("policy", help="'heuristic', 'ou', a checkpoint folder or 'onnx:PATH'")
    p.add_argument(
        "--canyons", default="eval", help="'eval' (all 20), 'eval:0-4', 'eval:2,7' or 'val:1000-1019'"
    )
    p.add_argument(
        "--hz", type=float, default=None,
        help="decisions per second [a checkpoint's: its training data's; else the calibrated default]",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--time-limit", type=float, default=45.0, help="seconds per run")
    p.add_argument("--which", default="best", help="checkpoint weights: best or last")
    p.add_argument("--seed", type=int, default=0, help="sensor-noise seed")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON line")
    p.add_argument("--no-video", action="store_true", help="skip video.mp4 of the first canyon")
    add_executor_arguments(p)


def run(args: argparse.Namespace) -> int:
    from depthq.evaluate.evaluate import EvalConfig, evaluate, parse_canyon_set

    config = EvalConfig(
        canyons=parse_canyon_set(args.canyons),
        time_limit_s=args.time_limit,
        seed=args.seed,
        which=args.which,
        decision_hz=args.hz,
    )
    result = evaluate(
        args.policy, args.out, config, workers=args.workers, device=args.device, video=not args.no_video,
        executor=executor_from(args),
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
