"""Driving against training length (docs/hard_canyons.md#training-length): one model of an oracle-gap
folder trained for the paper's 200 epochs with snapshots, every snapshot driven in the setup's `val`
canyons beside its validation loss and its agreement with the one-step oracle along its own runs.
Asks where, between the default's 40 epochs and the paper's 200, the driving turns, and what changes
with it.

    python -m research.training_length run OUT [--seeds 0] [--epochs 200] \\
        [--snapshots 20,40,80,120,160] [--net depth] [--average] [--figure PATH]

OUT is a `python -m research.oracle_gap run` folder (its dataset and canyons; the training is
its sweep's, `--set epochs=… --set snapshots=…`). The final weights are the sweep's own evaluation
(OUT/eval/<model>), each snapshot's is OUT/eval/<model>_epoch<N>; the agreements go to
OUT/training_length.json (each evaluation measured once). `--average` drives the mean of those weights
too (OUT/models/<model>_mean, Polyak averaging after the fact). It prints one row per seed and epoch, then
how well the validation loss and each diagnostic rank the points' driving (Spearman's ρ). The `eval`
canyons are never driven here.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/hard_canyons.md#training-length came from the code of commit e9c1943 (2026-11-26: the last change
of that page's tables).
"""

from __future__ import annotations

import argparse
import csv
import shutil
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import torch

from depthq.checkpoint import (
    METRICS,
    chosen_weights,
    read_config,
    read_sidecar,
    read_weights,
    snapshot_stem,
    weights_bytes,
    weights_stem,
    write_sidecar,
)
from depthq.configio import atomic_write_bytes, read_json, write_json
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import evaluate
from depthq.evaluate.oracle import Oracle
from depthq.evaluate.probe import measure_agreement
from depthq.pipeline.runner import run_sweep
from depthq.pipeline.sweep import parse_ints
from depthq.report.build import build_report
from depthq.report.cells import evaluation_summary, ranks_driving
from depthq.train.config import TrainConfig
from research.oracle_gap import Candidate, Setup, sweep_of

PROG = "python -m research.training_length"
MEASURED = "training_length.json"
COLUMNS = (  # the table's diagnostics: title, key of the agreement summary, format
    ("agrees, decisive", "agreement_decisive", ".0%"),
    ("agrees, last 2 s", "agreement_before_collision", ".0%"),
    ("score error (m)", "score_error", ".3f"),
    ("predicted spread (m)", "predicted_spread", ".3f"),
)


def candidate(epochs: int, snapshots: tuple[int, ...], net: str = "depth") -> Candidate:
    """The sweep variant that trains `epochs` and keeps the `snapshots`' weights. Its last point is
    one epoch's weights too: a Depth-Q-Net's final ones (average=0, the depth-first default's weight
    average left out), a Coll-Q-Net's best."""
    kept = "+".join(map(str, snapshots))
    final = ("average=0",) if TrainConfig(model=net, data="-").average else ()  # its default averages
    return Candidate(f"{epochs} epochs", (f"epochs={epochs}", f"snapshots={kept}", *final), net)


def averaged_name(model: str) -> str:
    """The checkpoint folder of `model`'s mean weights (`average_weights`)."""
    return f"{model}_mean"


def _points(model: str, epochs: int, snapshots: tuple[int, ...], average: bool = False
            ) -> list[tuple[int | str, str, str | None]]:
    """(epoch, evaluation folder name, weights) for every snapshot, then the final weights, then (with
    `average`) the mean of them all ("mean")."""
    return ([(e, f"{model}_epoch{e}", f"epoch:{e}") for e in snapshots] + [(epochs, model, None)]
            + ([("mean", averaged_name(model), None)] if average else []))


def average_weights(model: Path, epochs: int, snapshots: tuple[int, ...], out: Path) -> Path:
    """The mean of `model`'s snapshots' and final weights as a checkpoint folder `out` (the model's
    config.json, the mean as last.safetensors): Polyak averaging after the fact, which asks whether
    the driving's spread between neighbouring epochs is noise that averaging removes. Kept if written."""
    if (out / "last.safetensors").is_file():
        return out
    stems = [*(snapshot_stem(e) for e in snapshots), "last"]
    states = [read_weights(model / f"{stem}.safetensors")[0] for stem in stems]
    mean = {key: torch.stack([s[key] for s in states]).mean(0) if value.is_floating_point() else value
            for key, value in states[-1].items()}
    out.mkdir(parents=True, exist_ok=True)
    shutil.copy(model / "config.json", out / "config.json")
    write_sidecar(out, "last", {**read_sidecar(model, "last"), "averaged": stems})
    atomic_write_bytes(out / "last.safetensors",
                       weights_bytes(mean, {"epoch": str(epochs), "averaged": "+".join(stems)}))
    return out


def run(out: Path, setup: Setup, epochs: int, snapshots: tuple[int, ...], net: str = "depth",
        workers: int = 1, average: bool = False) -> int:
    """Per seed: the sweep's training and final evaluation, each snapshot's evaluation (with `average`,
    that of their mean weights too), and every evaluation's agreement with the one-step oracle
    (resumed: what exists is kept)."""
    if not snapshots or max(snapshots) >= epochs:
        raise ConfigError(f"snapshots {snapshots} must be epochs before the last ({epochs})")
    chosen = candidate(epochs, snapshots, net)
    path = out / MEASURED
    measured: dict[str, Any] = read_json(path) if path.is_file() else {}
    for seed in setup.seeds:
        sweep = sweep_of(setup, chosen, (seed,))
        run_sweep(sweep, out, finish=build_report)  # the training and its final weights' evaluation
        (model,) = (m.name for m in sweep.models())
        for epoch, name, weights in _points(model, epochs, snapshots, average):
            folder = out / "eval" / name
            if name != model and evaluation_summary(folder) is None:
                models = out / "models"
                checkpoint = (average_weights(models / model, epochs, snapshots, models / name)
                              if epoch == "mean" else models / model)
                print(f"{out}: evaluate {name}", flush=True)
                evaluate(str(checkpoint), folder, replace(sweep.eval_config(), weights=weights),
                         workers=workers, video=False)
            if name not in measured:
                measured[name] = measure_agreement(folder, Oracle(), out / "probe", predictions=True)
                write_json(path, measured)
    return 0


def rows(out: Path, setup: Setup, epochs: int, snapshots: tuple[int, ...], net: str = "depth",
         average: bool = False) -> list[dict[str, Any]]:
    """Every finished point: seed, epoch (of the weights driven: the sweep's own evaluation drives the
    checkpoint's choice, a Coll-Q-Net's best epoch), validation loss, driving and the diagnostic's
    measures."""
    measured = read_json(out / MEASURED) if (out / MEASURED).is_file() else {}
    found = []
    for seed in setup.seeds:
        (model,) = (m.name for m in sweep_of(setup, candidate(epochs, snapshots, net), (seed,)).models())
        metrics = out / "models" / model / METRICS
        if not metrics.is_file():
            continue
        with metrics.open() as f:
            val_loss = {int(r["epoch"]): float(r["val_loss"]) for r in csv.DictReader(f)}
        for epoch, name, _ in _points(model, epochs, snapshots, average):
            if name == model:  # the sweep drove the checkpoint's own choice: a Coll-Q-Net's best epoch
                folder = out / "models" / model
                stem = weights_stem(chosen_weights(read_config(folder), None))
                epoch = read_sidecar(folder, stem)["epoch"]
            summary = evaluation_summary(out / "eval" / name)
            if summary is not None and name in measured:
                found.append({"seed": seed, "epoch": epoch, "val_loss": val_loss.get(epoch), **measured[name],
                              "distance_to_collision_mean": summary["distance_to_collision_mean"],
                              "reached_end": summary["reached_end"]})
    return found


def table(points: list[dict[str, Any]]) -> str:
    """Markdown: one row per seed and epoch."""
    lines = ["| seed | epoch | validation loss | to first collision (m) | ends reached /20 | "
             + " | ".join(title for title, _, _ in COLUMNS) + " |",
             "|---|---|---|---|---|" + "---|" * len(COLUMNS)]
    for p in points:
        diagnostics = ("–" if p.get(key) is None else format(p[key], fmt) for _, key, fmt in COLUMNS)
        loss = "–" if p["val_loss"] is None else f"{p['val_loss']:.4f}"
        cells = [p["seed"], p["epoch"], loss, f"{p['distance_to_collision_mean']:.2f}",
                 p["reached_end"], *diagnostics]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    return "\n".join(lines)


def predicts(points: list[dict[str, Any]]) -> str:
    """Markdown: how well the validation loss and each diagnostic rank the points' distances to the first
    collision (Spearman's ρ over every seed and epoch; – under 3 points)."""
    lines = ["| measure | points | Spearman ρ with distance to first collision | p |", "|---|---|---|---|"]
    measures = (("validation loss", "val_loss"), *((title, key) for title, key, _ in COLUMNS))
    lines += [ranks_driving(title, points, key) for title, key in measures]
    return "\n".join(lines)


def plot(points: list[dict[str, Any]], path: Path) -> None:
    """Validation loss and distance to the first collision against the epoch, one line per seed (the
    mean weights' distance, where driven, a dashed level)."""
    fig, (loss, drive) = plt.subplots(1, 2, figsize=(10, 3.8))
    for seed in sorted({p["seed"] for p in points}):
        mine = [p for p in points if p["seed"] == seed and p["epoch"] != "mean"]
        loss.plot([p["epoch"] for p in mine], [p["val_loss"] for p in mine], "o-", label=f"seed {seed}")
        distances = [p["distance_to_collision_mean"] for p in mine]
        (line,) = drive.plot([p["epoch"] for p in mine], distances, "o-", label=f"seed {seed}")
        for p in points:  # the mean weights: a level in the seed's colour
            if p["seed"] == seed and p["epoch"] == "mean":
                drive.axhline(p["distance_to_collision_mean"], color=line.get_color(), ls="--",
                              label=f"seed {seed}, mean weights")
    loss.set(xlabel="epoch", ylabel="validation loss", title="validation loss")
    drive.set(xlabel="epoch", ylabel="m", title="distance to the first collision (val canyons)")
    for ax in (loss, drive):
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("action", choices=("run", "table"), help="run (resumed) and tabulate, or tabulate")
    parser.add_argument("out", type=Path, help="an oracle-gap folder (its dataset and val canyons)")
    parser.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1")
    parser.add_argument("--epochs", type=int, default=200, help="the training's length (the paper's 200)")
    parser.add_argument("--snapshots", default="20,40,80,120,160", help="epochs whose weights are driven too")
    parser.add_argument("--net", choices=("depth", "coll"), default="depth", help="the network")
    parser.add_argument("--average", action="store_true",
                        help="also drive the mean of the snapshots' and final weights (Polyak averaging)")
    parser.add_argument("--figure", type=Path, help="where to draw loss and driving against the epoch")
    args = parser.parse_args(argv)

    def work() -> int:
        if not (args.out / "data").is_dir():
            raise ConfigError(f"{args.out}: not an oracle-gap folder (no data/ in it)")
        setup = Setup(seeds=parse_ints(args.seeds, "--seeds"))
        snapshots = parse_ints(args.snapshots, "--snapshots")
        if args.action == "run":
            run(args.out, setup, args.epochs, snapshots, args.net, average=args.average)
        points = rows(args.out, setup, args.epochs, snapshots, args.net, args.average)
        print(table(points))
        print()
        print(predicts(points))
        if args.figure:
            plot(points, args.figure)
        return 0

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
