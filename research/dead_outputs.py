"""Dead outputs and the straight-through bin gradient (docs/research/dead_outputs.md): the default
Depth-Q-Net (`bin_gradient=relu`) against `bin_gradient=straight_through`, trained on one dataset at
the default budget, their dead outputs counted on its validation frames, each driven in `val` canyons.

    python -m research.dead_outputs run DATA OUT [--seeds 0,1] [--runs 200] [--canyons hard/val:1000-1019]
        [--look textured] [--gradients relu,straight_through]
    python -m research.dead_outputs table OUT

`run` trains (or resumes) one model per gradient and seed into OUT/models, counts its dead outputs and
drives it (OUT/eval, skipped where a summary exists), seed-major so a partial run has whole rows;
OUT/results.json keeps what is measured (runs of other seeds may share OUT, but not a seed: two
trainings in one model folder at once collide). `table` prints
the Markdown table. The `eval` canyons are refused. A research script (research/, not in the wheel;
run from a checkout's root).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from depthq.configio import read_json, write_json
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.networks import DepthSettings
from depthq.pipeline.sweep import parse_ints
from depthq.report.cells import mean_interval
from depthq.sim.canyon import split_family
from depthq.train.config import TrainConfig
from depthq.train.dead_outputs import count_dead_outputs
from depthq.train.trainer import train

GRADIENTS = ("relu", "straight_through")


def name_of(gradient: str, runs: int, seed: int) -> str:
    return f"depth_n{runs}_s{seed}_{gradient}"


def run(data: Path, out: Path, seeds: tuple[int, ...], runs: int, canyons: str, look: str | None,
        gradients: tuple[str, ...]) -> int:
    """Every (seed, gradient): trained, its dead outputs counted, driven; results.json after each."""
    if split_family(canyons)[1].startswith("eval"):
        raise ConfigError(f"--canyons {canyons!r}: the eval canyons are the test set; choose in val ones")
    path = out / "results.json"
    results: dict[str, Any] = read_json(path) if path.is_file() else {}
    config = EvalConfig(canyons=parse_canyon_set(canyons), look=look)
    for seed in seeds:
        for gradient in gradients:
            name = name_of(gradient, runs, seed)
            folder = out / "models" / name
            train(TrainConfig(model="depth", data=str(data), runs=runs, seed=seed,
                              settings=DepthSettings(bin_gradient=gradient)),
                  folder, progress=False)
            row = {**results.get(name, {}), "gradient": gradient, "seed": seed, "runs": runs}
            found = count_dead_outputs(folder)
            row.update(dead=list(found.dead), outputs=found.outputs, frames=found.frames)
            print(f"{name}: {found}", flush=True)
            evaluation = out / "eval" / name
            if not (evaluation / "summary.json").is_file():
                evaluate(str(folder), evaluation, config, workers=1, progress=False, video=False)
            summary = read_json(evaluation / "summary.json")
            s = summary["summary"]
            row.update(canyons=canyons, look=look, distance_to_collision=s["distance_to_collision_mean"],
                       ends=s["reached_end"], collisions=s["collisions"],
                       val_loss=summary.get("offline", {}).get("value"))
            print(f"{name}: {s['distance_to_collision_mean']:.2f} m to the first collision, "
                  f"{s['reached_end']} ends", flush=True)
            # merged with the file as it is now: a run of other seeds may share OUT
            results = {**(read_json(path) if path.is_file() else {}), name: row}
            write_json(path, results)
    print(table(out))
    return 0


def table(out: Path) -> str:
    """Markdown: per gradient, the dead outputs per seed, the distance to the first collision (mean over
    seeds, 95 % interval from 2), ends reached and the validation loss (the offline metric)."""
    results: dict[str, Any] = read_json(out / "results.json")
    lines = ["| bin gradient | seeds | dead outputs per seed (bins) | m to first collision | ends per seed | "
             "val loss per seed |", "|---|---|---|---|---|---|"]
    for gradient in GRADIENTS:
        rows = sorted((r for r in results.values() if r["gradient"] == gradient), key=lambda r: r["seed"])
        if not rows:
            continue
        dead = ", ".join(f"{len(r['dead'])}/{r['outputs']}" + (f" ({' '.join(map(str, r['dead']))})"
                                                                if r["dead"] else "") for r in rows)
        distance = mean_interval([r["distance_to_collision"] for r in rows], ".2f")
        ends = ", ".join(str(r["ends"]) for r in rows)
        loss = ", ".join(f"{r['val_loss']:.4f}" if r.get("val_loss") is not None else "–" for r in rows)
        lines.append(f"| {gradient} | {len(rows)} | {dead} | {distance} | {ends} | {loss} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.dead_outputs",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("action", choices=("run", "table"))
    parser.add_argument("paths", nargs="+", type=Path, help="run: DATA OUT; table: OUT")
    parser.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1")
    parser.add_argument("--runs", type=int, default=200, help="training runs")
    parser.add_argument("--canyons", default="hard/val:1000-1019", help="val canyons to drive in")
    parser.add_argument("--look", default=None, help="the look to drive in (none: the family's own)")
    parser.add_argument("--gradients", default=",".join(GRADIENTS), help="bin gradients, comma-separated")
    args = parser.parse_args(argv)

    def work() -> int:
        if args.action == "table":
            print(table(args.paths[-1]))
            return 0
        if len(args.paths) != 2:
            raise ConfigError("run takes DATA OUT")
        gradients = tuple(args.gradients.split(","))
        for gradient in gradients:
            if gradient not in GRADIENTS:
                raise ConfigError(f"--gradients: {gradient!r} is not one of {GRADIENTS}")
        return run(*args.paths, parse_ints(args.seeds, "--seeds"), args.runs, args.canyons, args.look,
                   gradients)

    return guarded("python -m research.dead_outputs", work)


if __name__ == "__main__":
    sys.exit(main())
