"""Calibration of the hard canyon family on `val` canyons only (docs/hard_canyons.md).

    python docs/hard_canyons.py [OUT]        # the table below, and OUT/hard_canyons.png (default docs/)

For each candidate generator config (narrower → curvier → more pillars), without a camera (only the
LiDAR decides, as `depthq.report.probe` does):

- the heuristic expert drives the 20 canyons hard/val:1000-1019, seeded as `depthq evaluate` seeds
  them (sensor noise seed = canyon index), with the family's time limit (derived from its length);
- OU exploration drives `--ou-runs` collection runs in hard/train canyons, as `depthq collect` does
  (seed 0): how long runs are, how many reach `min_frames`, how many end in a bump or at the end.

The hard family is the hardest candidate whose heuristic still passes >= 19 of the 20 val canyons.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

import depthq  # noqa: F401  (MUJOCO_GL before mujoco)
from depthq.control.heuristic import DepthHeuristic
from depthq.data.collect import CollectConfig, collect_run, exploration_env
from depthq.data.labels import MIN_FRAMES
from depthq.evaluate.evaluate import drive, parse_canyon_set
from depthq.evaluate.metrics import summarize
from depthq.sim.canyon import HARD_CANYON, CanyonConfig, ObstacleConfig, _time_to_end
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.world import WorldConfig, world_for

CANYONS = "hard/val:1000-1019"
OU_RUNS = 100
BASE = replace(HARD_CANYON, obstacles=ObstacleConfig())
THIN = ObstacleConfig(radius=0.15, min_gap=0.6)  # thin pillars, a narrower free passage


def wide(width: float, pillars: int = 0, heading: float = math.pi / 4) -> CanyonConfig:
    """The family's generator at another width, pillar count (ObstacleConfig's size) and curvature."""
    pillars_config = ObstacleConfig(count=pillars)
    start = (-width / 2, 0.0)  # the spawn in the middle
    return replace(BASE, width=width, start=start, heading_scale=heading, obstacles=pillars_config)


# name → generator config; "chosen" is the family's (depthq.sim.canyon.HARD_CANYON)
CANDIDATES: dict[str, CanyonConfig] = {
    "w2.0 π/4": wide(2.0),
    "w2.0 π/4, 6 thin pillars": replace(wide(2.0), obstacles=replace(THIN, count=6)),
    "w2.5 π/4": wide(2.5),
    "w2.75 π/4": wide(2.75),
    "w3.0 π/4": wide(3.0),
    "w3.0 π/6 (the paper's walls, 50 pieces)": wide(3.0, heading=math.pi / 6),
    "w2.75 π/3.5, 4 pillars": wide(2.75, 4, math.pi / 3.5),
    "w2.75 π/4, 4 pillars": wide(2.75, 4),
    "w2.75 π/4, 6 pillars": wide(2.75, 6),
    "w2.75 π/4, 8 pillars": wide(2.75, 8),
    "w2.75 π/4, 10 pillars": wide(2.75, 10),
}


def hard_world(canyon: CanyonConfig, **changes) -> WorldConfig:
    return replace(world_for(WorldConfig(**changes), "hard"), canyon=canyon)


def heuristic_row(canyon: CanyonConfig) -> dict:
    limit = _time_to_end(canyon)
    env = CanyonEnv(EnvConfig(world=hard_world(canyon), time_limit_s=limit), camera=False)
    expert = DepthHeuristic()
    try:
        runs = [drive(expert, env, expert, c, int(c.split(":")[1])) for c in parse_canyon_set(CANYONS)]
    finally:
        env.close()
    return {"time_limit_s": limit, **summarize(runs), "runs_detail": runs}


def ou_row(canyon: CanyonConfig, n: int = OU_RUNS) -> dict:
    base = exploration_env()
    env_config = replace(base, world=replace(hard_world(canyon), max_yaw_rate=base.world.max_yaw_rate))
    config = CollectConfig(runs=n, val_runs=0, env=env_config)
    env = CanyonEnv(env_config, camera=False)
    try:
        runs = [collect_run(env, config, 0, "train", i).meta for i in range(n)]
    finally:
        env.close()
    lengths = np.array([r.n_frames for r in runs])
    kept = lengths[lengths >= MIN_FRAMES]
    return {
        "kept": len(kept) / n,
        "frames": float(kept.mean()) if len(kept) else 0.0,
        "bumped": float(np.mean([r.collision for r in runs])),
        "ended": float(np.mean([r.end_reason == "end" for r in runs])),
    }


def measure(canyon: CanyonConfig) -> tuple[dict, dict]:
    return heuristic_row(canyon), ou_row(canyon)


def main(out: Path) -> None:
    head = (
        "| candidate | heuristic success | collisions | to collision (m) | closest mean / min (m) "
        "| OU kept | OU frames/kept run | OU bumped | OU at end |"
    )
    print(f"heuristic in {CANYONS} (camera off); OU: {OU_RUNS} runs in hard/train:0-{OU_RUNS - 1}\n")
    print(head + "\n|" + "---|" * head.count(" | ") + "---|")
    chosen = None
    with ProcessPoolExecutor(2, mp_context=mp.get_context("spawn")) as pool:
        rows = list(pool.map(measure, CANDIDATES.values()))
    for (name, canyon), (h, ou) in zip(CANDIDATES.items(), rows, strict=True):
        mark = " (chosen)" if canyon == HARD_CANYON else ""
        print(
            f"| {name}{mark} | {h['successes']}/{h['runs']} | {h['collisions']} "
            f"| {h['distance_to_collision_mean']:.1f} | {h['closest_mean']:.2f} / {h['closest_min']:.2f} "
            f"| {ou['kept']:.0%} | {ou['frames']:.1f} | {ou['bumped']:.0%} | {ou['ended']:.0%} |",
            flush=True,
        )
        if mark:
            chosen = h
    if chosen is not None:
        picture(chosen["runs_detail"][:4], out / "hard_canyons.png")


def picture(runs: list[dict], path: Path) -> None:
    """Top-down maps of a few val canyons with the heuristic's runs, small."""
    from depthq.sim.canyon import CanyonId, generate_canyon
    from depthq.sim.topdown import plot_runs

    items = [(generate_canyon(CanyonId.parse(r["canyon"])), r["poses"]) for r in runs]
    fig = plot_runs(items, [f"{r['canyon']}: {r['end_reason']}" for r in runs], cols=len(runs))
    for ax, (canyon, _) in zip(fig.axes, items, strict=False):
        ax.set_ylim(-2.5, canyon.centre[:, 1].max() + 1)
    fig.set_size_inches(7, 5.5)
    fig.tight_layout()
    fig.savefig(path, dpi=80)

if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent)
