"""Drive one policy through one canyon; write a top-down map and a few camera frames."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image

from depthq.errors import ConfigError
from depthq.nets.device import DEVICE_HELP, resolve_device
from depthq.sim.canyon import FAMILIES


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--policy", default="heuristic", help="'heuristic', 'ou' or a checkpoint folder")
    p.add_argument("--canyon", default="eval:0", help="canyon id, e.g. eval:0, train:12 or hard/eval:0")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--device", default="auto", help=DEVICE_HELP)
    p.add_argument("--seed", type=int, default=0, help="sensor-noise and policy seed")
    p.add_argument(
        "--time-limit", type=float, default=None,
        help="seconds before the run is cut [the canyon family's: 45 for the paper's]",
    )
    p.add_argument("--hz", type=float, default=None,
                   help="decisions (camera frames) per second [a checkpoint's: the one it records]")
    p.add_argument("--weights", "--which", dest="weights", default=None,
                   help="checkpoint weights: best, last or epoch:N [the checkpoint's own, train --weights]; "
                   "--which: its old name")
    p.add_argument("--frames", type=int, default=4, help="camera frames to save, evenly spaced")
    p.add_argument("--json", action="store_true", help="print one machine-readable JSON line")


def run(args: argparse.Namespace) -> int:
    # MuJoCo and torch: when this verb runs, not at the CLI's startup
    from depthq.evaluate.online import decision_rate
    from depthq.policies.registry import make_policy
    from depthq.policies.spec import PolicySpec
    from depthq.sim.env import CanyonEnv, EnvConfig, parse_canyon
    from depthq.sim.world import WorldConfig, world_for

    canyon = parse_canyon(args.canyon)
    if args.frames < 0:
        raise ConfigError(f"--frames must be >= 0, got {args.frames}")
    device = str(resolve_device(args.device))
    spec = PolicySpec.parse(args.policy)
    policy = make_policy(spec, seed=args.seed, weights=args.weights, device=device)
    world = WorldConfig(decision_hz=decision_rate(spec) if args.hz is None else args.hz)
    limit = FAMILIES[canyon.family].time_limit_s if args.time_limit is None else args.time_limit
    env = CanyonEnv(EnvConfig(world=world_for(world, canyon.family), time_limit_s=limit))
    try:
        obs, info = env.reset(seed=args.seed, options={"canyon": canyon})
        policy.reset(args.seed)
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
