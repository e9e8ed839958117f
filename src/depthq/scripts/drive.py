"""Drive one policy through one canyon; write a top-down map and a few camera frames."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image

from depthq.blocks.device import DEVICE_HELP, resolve_device
from depthq.blocks.migrations import RENAMED_EVAL_SETTINGS
from depthq.errors import ConfigError
from depthq.flags import add_config_arguments, config_from_args, flag_name

# EvalConfig's flags drive shares with `depthq evaluate`, and their spellings from before they were
# made from it or were a network's own (aliases: --rule for --depth.rule); the canyon is drive's own
# (one), and it drives no lock-step batch.
_ALIASES = {"time_limit_s": ("--time-limit",), "decision_hz": ("--hz",), "weights": ("--which",),
            **{path: (flag_name(old),) for old, path in RENAMED_EVAL_SETTINGS.items()}}
_HELP = {"seed": "drive seeds its one run and policy with it as it is, whatever the canyon"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--policy", default="heuristic", help="'heuristic', 'ou' or a checkpoint folder")
    p.add_argument("--canyon", default="eval:0", help="canyon id, e.g. eval:0, train:12 or hard/eval:0")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    p.add_argument("--frames", type=int, default=4, help="camera frames to save, evenly spaced")
    p.add_argument("--json", action="store_true", help="print one machine-readable JSON line")
    from depthq.evaluate.online import EvalConfig  # MuJoCo: only when this verb's flags are built

    add_config_arguments(p, EvalConfig, exclude=("canyons", "lockstep"), aliases=_ALIASES, more_help=_HELP)


def run(args: argparse.Namespace) -> int:
    # MuJoCo and torch: when this verb runs, not at the CLI's startup
    from depthq.evaluate.online import EvalConfig, at_policy_rate
    from depthq.policies.registry import make_policy
    from depthq.policies.spec import PolicySpec
    from depthq.sim.env import CanyonEnv, parse_canyon

    canyon = parse_canyon(args.canyon)
    if args.frames < 0:
        raise ConfigError(f"--frames must be >= 0, got {args.frames}")
    device = str(resolve_device(args.device))
    spec = PolicySpec.parse(args.policy)
    config = at_policy_rate(config_from_args(EvalConfig, args, canyons=(str(canyon),)), spec)
    policy = make_policy(spec, seed=config.seed, weights=config.weights, device=device,
                         acting=config.acting)
    env = CanyonEnv(config.env)
    seed = config.seed
    try:
        obs, info = env.reset(seed=seed, options={"canyon": canyon})
        policy.reset(seed)
        frames = [obs["image"].copy()]
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(np.array([policy.act(obs)], np.float32))
            frames.append(obs["image"].copy())
            done = terminated or truncated
        args.out.mkdir(parents=True, exist_ok=True)
        env.top_down(str(args.out / "top_down.png"))
        picks = np.linspace(0, len(frames) - 1, args.frames).round().astype(int) if args.frames else []
        for k in picks:
            Image.fromarray(frames[k]).save(args.out / f"frame_{k:04d}.png")
    finally:
        env.close()
    result = {
        "policy": args.policy,
        "canyon": str(canyon),
        "distance": round(info["distance"], 3),
        "path_length": round(info["path_length"], 3),
        "time": info["time"],
        "end_reason": info["end_reason"],
        "progress": round(info["progress"], 3),
        "closest": round(info["closest"], 3),
        "out": str(args.out),
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"{args.policy} in {canyon}: {result['distance']:.2f} m from the spawn "
            f"in {result['time']:.1f} s, ended by {result['end_reason']}; map and frames in {args.out}"
        )
    return 0
