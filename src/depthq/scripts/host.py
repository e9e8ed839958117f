"""Print this machine's fingerprint (CPU, BLAS, torch, numpy, mujoco), as checkpoints record it."""

from __future__ import annotations

import argparse
import json


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--threads", type=int, default=None,
                   help="torch threads to record (default: this process's setting)")


def run(args: argparse.Namespace) -> int:
    from depthq.errors import ConfigError
    from depthq.host import host_fingerprint  # torch and mujoco: when this verb runs

    if args.threads is not None and args.threads < 1:
        raise ConfigError(f"--threads must be at least 1, got {args.threads}")
    print(json.dumps(host_fingerprint(args.threads), indent=2))
    return 0
