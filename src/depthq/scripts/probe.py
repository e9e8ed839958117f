"""Fidelity probe: OU run statistics (Table II calibration), the one-step oracle, a small Depth-Q-Net."""

from __future__ import annotations

import argparse
from pathlib import Path

from depthq.configio import write_json
from depthq.errors import ConfigError
from depthq.flags import add_config_arguments, config_from_args
from depthq.sim.canyon import split_family


def _rates(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--hz must be comma-separated rates, e.g. 10,5,4; got {text!r}") from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hz", default="4", help="candidate decision rates, comma-separated, e.g. 10,5,4")
    p.add_argument("--parts", default="stats,oracle,dqn",
                   help="some of stats, oracle, dqn, agreement, dead (see depthq.evaluate.probe)")
    p.add_argument("--oracle", default="depth:1",
                   help="oracles of the oracle and agreement parts, comma-separated: depth:K[:RULE] (the "
                   "true bins 1..K frames ahead of each action held) or coll:K (a bump within K frames)")
    p.add_argument("--evals", default="",
                   help="evaluation folders (depthq evaluate's --out) for the agreement part, "
                   "comma-separated")
    p.add_argument("--checkpoints", default="",
                   help="checkpoint folders for the dead part (how many of a Depth-Q-Net's outputs are 0 "
                   "for every validation frame and candidate action), comma-separated")
    p.add_argument("--predictions", action="store_true",
                   help="agreement: also re-predict a checkpoint's values at every step (renders each frame)")
    p.add_argument("--stats-runs", type=int, default=300, help="OU runs per rate for the statistics")
    p.add_argument("--runs", type=int, default=200, help="training runs of the small Depth-Q-Net")
    p.add_argument("--epochs", type=int, default=40, help="training epochs of the small Depth-Q-Net")
    p.add_argument(
        "--canyons", default="val:1000-1019",
        help="val canyons to drive in (never eval), e.g. hard/val:1000-1019",
    )
    p.add_argument("--out", type=Path, required=True, help="folder for probe.json and the small runs")
    from depthq.sim.world import WorldConfig  # MuJoCo: only when this verb's flags are built

    add_config_arguments(p, WorldConfig, only=("family",),
                         more_help={"family": "the OU statistics' canyons"})


def run(args: argparse.Namespace) -> int:
    from depthq.evaluate.probe import format_stats, probe  # MuJoCo and torch: when this verb runs

    if split_family(args.canyons)[1].startswith("eval"):
        raise ConfigError(f"--canyons {args.canyons!r}: the eval canyons are the test set; probe in val ones")
    from depthq.evaluate.oracle import Oracle
    from depthq.sim.world import WorldConfig

    parts = tuple(args.parts.split(","))
    oracles = tuple(Oracle.parse(text) for text in args.oracle.split(","))
    evaluations = tuple(Path(text) for text in args.evals.split(",") if text)
    checkpoints = tuple(Path(text) for text in args.checkpoints.split(",") if text)
    family = config_from_args(WorldConfig, args).family
    result = probe(_rates(args.hz), parts, args.out, args.stats_runs, args.runs, args.canyons, args.epochs,
                   family, oracles, evaluations, args.predictions, checkpoints)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "probe.json", result)  # strict JSON, written atomically
    if "stats" in result:
        print(format_stats(result["stats"]))
    for row in result.get("oracle", []):
        print(f"oracle {row['oracle']} at {row['decision_hz']:g} Hz in {args.canyons}: ends reached "
              f"{row['reached_end']}/{row['canyons']}, successes {row['successes']}, progress "
              f"{row['progress_mean']:.2f} m")
    for row in result.get("agreement", []):
        print(f"{row['policy']} vs oracle {row['oracle']}: agrees on {row['agreement_decisive']:.0%} of "
              f"{row['decisive_steps']} decisive steps, {row['agreement_before_collision'] or 0:.0%}"
              f" in the last 2 s before its {row['collisions']} collisions ({row['collisions_with_pillar']} "
              f"with a pillar); {row['distance_to_collision_mean']:.2f} m to the first collision")
    for row in result.get("dead", []):
        print(f"{row['checkpoint']}: {row['text']}")
    for hz, s in result.get("dqn", {}).items():
        print(f"Depth-Q-Net on {args.runs} runs at {hz} Hz in {args.canyons}: {s['successes']}/{s['runs']}, "
              f"{s['distance_mean']:.2f} m")
    return 0
