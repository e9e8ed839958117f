"""Which weights a checkpoint acts with, looked at on its own validation frames
(docs/research/weights_check.md).

    python -m research.weights_check CHECKPOINT [--weights final,best,average] [--frames 500]
    python -m research.weights_check CHECKPOINT --canyons hard/val:1000-1004 --out OUT
    python -m research.weights_check CHECKPOINT --parts
    python -m research.weights_check --margins CHECKPOINT [CHECKPOINT ...]

For each weights choice (default: final, best and, where the training kept it, average): the bins it
predicts as 0 for every candidate action on every frame (dead: a 0 is no reading, so its policy never
sees that bin), the share of candidates whose nearest predicted reading is a phantom (above 0 but
nearer than the LiDAR's minimum range, so no label had it) and the bins that give them, the median
spread of its candidates' scores, and how often each action wins, on the first `--frames` validation
frames of the checkpoint's dataset (from the feature cache). With
`--canyons`, each choice is also driven there (`depthq evaluate --weights W`, into OUT/<weights>/):
the distance to the first collision beside what the frames show. With `--parts` (a depth_first head),
the score spread of every pairing of one choice's perception with another's dynamics: which part of a
choice moves its actions. `--margins`: for any number of checkpoints, only how far each one's weight
average's validation loss is above its final weights' and the weights it acts with. Make choices on
`val` canyons.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from depthq.blocks.heads import DepthFirstHead
from depthq.checkpoint import (
    AVERAGE_TOLERANCE_SE,
    average_margin,
    chosen_weights,
    dataset_record,
    read_config,
    weights_stem,
)
from depthq.configio import write_json
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.lock import exclusive
from depthq.policies.qnet import QNetPolicy
from depthq.report.tables import markdown
from depthq.sim.sensors import LidarConfig
from depthq.train.dead_outputs import dead_outputs, net_features, split_features

PROG = "python -m research.weights_check"
DEAD = 1e-6  # m: a bin predicted at or below this counts as no phantom reading


def available(folder: Path) -> tuple[str, ...]:
    """The weights choices a checkpoint holds: final and best, and average when its training kept one."""
    return tuple(choice for choice in ("final", "best", "average")
                 if (Path(folder) / f"{weights_stem(choice)}.safetensors").is_file())


def range_min(folder: Path) -> float:
    """The LiDAR's minimum range in the checkpoint's dataset (m; a robot's recording: the default
    LiDAR's): no bin it labels is nearer."""
    env = dataset_record(read_config(folder)).env
    return float(env["world"]["lidar"]["range_min"]) if env else LidarConfig().range_min


def measure(folder: Path, weights: tuple[str, ...], frames: int = 500) -> dict[str, dict[str, Any]]:
    """Per weights choice: dead bins, phantom readings (their share of candidates and their bins), the
    median and 90th percentile of the candidates' score spread, and the share of frames on which each
    action wins."""
    cached = split_features(folder, "val", frames)
    floor = range_min(folder)
    out = {}
    for choice in weights:
        policy = QNetPolicy.from_checkpoint(folder, weights=choice)
        # (F, A, 26) bins or (F, A) probabilities
        values = policy.candidate_values(net_features(policy.net, cached))
        actions = np.asarray(policy.actions)
        spreads = score_spreads(policy, values)
        chosen = np.array([policy.network.choose(v, actions) for v in values])
        dead, phantom, phantom_bins = np.array([], int), 0.0, []
        if values.ndim == 3:  # bins: (F, A, n_bins)
            dead = np.array(dead_outputs(values), int)
            readings = np.where(values > DEAD, values, np.inf)
            nearest = readings.min(axis=2)
            ghost = nearest < floor
            phantom = float(ghost.mean())
            phantom_bins = sorted(set(readings.argmin(axis=2)[ghost].tolist()))
        out[choice] = {
            "frames": len(values),
            "dead_bins": dead.tolist(),
            "phantom": phantom,
            "phantom_bins": phantom_bins,
            "spread_median": float(np.median(spreads)),
            "spread_p90": float(np.percentile(spreads, 90)),
            "chosen": {f"{a:+g}": float(np.mean(chosen == a)) for a in actions},
        }
    return out


def score_spreads(policy: QNetPolicy, values: np.ndarray) -> np.ndarray:
    """Per frame of `values` (`candidate_values`), the spread of its candidates' scores (m or probability)."""
    scores = np.stack([policy.network.scores(v) for v in values])
    return scores.max(1) - scores.min(1)


def parts(folder: Path, weights: tuple[str, ...], frames: int = 500) -> dict[str, dict[str, float]]:
    """A depth_first head's score spread with one choice's perception (rows) and another's dynamics
    (columns): which part of a weights choice changes its actions."""
    cached = split_features(folder, "val", frames)
    policies = {choice: QNetPolicy.from_checkpoint(folder, weights=choice) for choice in weights}
    if not all(isinstance(p.net.head, DepthFirstHead) for p in policies.values()):
        raise ConfigError(f"{folder}: --parts needs a depth_first head (perception, then dynamics)")
    out: dict[str, dict[str, float]] = {}
    for perceive, policy in policies.items():
        out[perceive] = {}
        for dynamics, other in policies.items():
            mixed = copy.deepcopy(policy)
            mixed.net.head.output["dynamics"].load_state_dict(other.net.head.output["dynamics"].state_dict())
            values = mixed.candidate_values(net_features(mixed.net, cached))  # its perception's trunk
            out[perceive][dynamics] = float(np.median(score_spreads(mixed, values)))
    return out


def parts_table(measured: dict[str, dict[str, float]]) -> str:
    """Markdown: perception's choice by row, dynamics' by column, the median score spread in each cell."""
    choices = list(measured)
    lines = ["| perception \\ dynamics | " + " | ".join(choices) + " |", "|" + "---|" * (len(choices) + 1)]
    lines += ["| " + " | ".join([p, *(f"{measured[p][d]:.3f}" for d in choices)]) + " |" for p in choices]
    return "\n".join(lines)


def drive(folder: Path, weights: tuple[str, ...], canyons: str, out: Path) -> dict[str, dict[str, Any]]:
    """Each weights choice driven in `canyons` (one worker): its summary, from OUT/<weights>/."""
    config = EvalConfig(canyons=parse_canyon_set(canyons))
    return {choice: evaluate(str(folder), out / choice, replace(config, weights=choice), workers=1,
                             progress=False, video=False)["summary"]
            for choice in weights}


def table(measured: dict[str, dict[str, Any]], driven: dict[str, dict[str, Any]] | None = None) -> str:
    """Markdown: one row per weights choice."""
    actions = next(iter(measured.values()))["chosen"]
    head = ["weights", "dead bins", "phantom readings (bins)", "score spread, median (p90)",
            *(f"chooses {a}" for a in actions)]
    if driven:
        head.append("driven: m to first collision (ends)")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for choice, m in measured.items():
        cells = [choice, ", ".join(map(str, m["dead_bins"])) or "none",
                 f"{m['phantom']:.1%}" + (f" ({', '.join(map(str, m['phantom_bins']))})"
                                           if m["phantom_bins"] else ""),
                 f"{m['spread_median']:.3f} ({m['spread_p90']:.3f})",
                 *(f"{share:.0%}" for share in m["chosen"].values())]
        if driven:
            s = driven[choice]
            cells.append(f"{s['distance_to_collision_mean']:.2f} ({s['reached_end']})")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def margins_table(checkpoints: list[Path]) -> str:
    """Markdown, a row per checkpoint: its weight average's validation loss over the final weights', in
    standard errors (`average_margin`; the tolerance `AVERAGE_TOLERANCE_SE`), and the weights it acts
    with by default, largest margin first."""
    rows = []
    for folder in checkpoints:
        record = read_config(folder)
        margin = average_margin(folder, record)
        rows.append((margin if margin is not None else -np.inf, {
            "checkpoint": str(folder), "average − final, SE": "–" if margin is None else f"{margin:+.2f}",
            "acts with": chosen_weights(record, None, folder)}))
    rows.sort(key=lambda r: -r[0])
    return (f"tolerance: {AVERAGE_TOLERANCE_SE:+.2f} SE\n\n" + markdown([row for _, row in rows]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    parser.add_argument("checkpoint", type=Path, nargs="+",
                        help="a checkpoint folder (with --margins: any number of them)")
    parser.add_argument("--margins", action="store_true",
                        help="only each checkpoint's weight-average margin and the weights it acts with")
    parser.add_argument("--weights", default=None,
                        help="weights choices, comma-separated: final, best, average, epoch:N (default: "
                        "final, best and average where kept)")
    parser.add_argument("--frames", type=int, default=500, help="validation frames looked at")
    parser.add_argument("--canyons", default=None, help="also drive each choice in these canyons (val ones)")
    parser.add_argument("--out", type=Path, default=None,
                        help="where weights_check.json goes (with --canyons: and the evaluations)")
    parser.add_argument("--parts", action="store_true",
                        help="also pair each choice's perception with each choice's dynamics (depth_first)")
    args = parser.parse_args(argv)

    def work() -> int:
        if args.margins:
            print(margins_table(args.checkpoint))
            return 0
        if len(args.checkpoint) > 1:
            raise ConfigError(f"one checkpoint at a time, got {len(args.checkpoint)} (or --margins)")
        checkpoint = args.checkpoint[0]
        weights = available(checkpoint) if args.weights is None else tuple(args.weights.split(","))
        for choice in weights:
            weights_stem(choice)  # a bad choice fails here, before any work
        if args.frames < 1:
            raise ConfigError(f"--frames must be >= 1, got {args.frames}")
        if args.canyons is not None and args.out is None:
            raise ConfigError("--canyons needs --out, the evaluations' folder")
        with exclusive(args.out) if args.out is not None else contextlib.nullcontext():
            measured = measure(checkpoint, weights, args.frames)
            mixed = parts(checkpoint, weights, args.frames) if args.parts else None
            driven = drive(checkpoint, weights, args.canyons, args.out) if args.canyons else None
            if args.out is not None:
                write_json(args.out / "weights_check.json",
                           {"measured": measured, "parts": mixed, "driven": driven})
        print(table(measured, driven))
        if mixed:
            print("\n" + parts_table(mixed))
        return 0

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
