"""The ablation ladder (docs/ablation.md): from our defaults to the paper's settings, one factor at a
time and all together, both networks, 200 and 500 runs, seeds 0 and 1, in `val` canyons only; then
the rungs beyond the paper (seed 0; the label's horizon seeds 0 and 1).

    python -m depthq.experiments.ablation run hard runs/ladder-hard    # runs (or resumes) every sweep
    python -m depthq.experiments.ablation table hard runs/ladder-hard  # ablation.md, .png of what finished
    python -m depthq.experiments.ablation run paper runs/ladder-paper  # paper canyons: val_choices.md's gaps

Every rung is a `depthq sweep` into OUT/4hz (or OUT/10hz: another rate is another dataset), so an
interrupted ladder resumes with the same command and a rung shared with another ladder is reused.
Rungs run seed 0 first, so a partial ladder already has a whole column of rungs.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.configio import read_json
from depthq.data.labels import HORIZON
from depthq.errors import guarded
from depthq.nets.checkpoint import chosen_weights, read_config, read_sidecar, weights_stem
from depthq.pipeline.presets import get_preset
from depthq.pipeline.runner import run_sweep
from depthq.pipeline.sweep import Sweep, parse_setting, retarget, widened
from depthq.report.build import build_report
from depthq.report.cells import mean_interval

SIZES, SEEDS = (200, 500), (0, 1)
PAPER_SETTINGS = ("action_scale=1", "dropout=0.5", "trunk=efficientnet_lite0", "epochs=200", "weights=final")


@dataclass(frozen=True)
class Rung:
    """One step of the ladder: training settings (`depthq sweep --set`), per network, and a rate."""

    name: str
    sets: tuple[str, ...] = ()
    nets: tuple[str, ...] = ("depth", "coll")
    hz: float = 4.0
    coll_sets: tuple[str, ...] = ()  # Coll-Q-Net only (the paper's lr differs between the networks)
    seeds: tuple[int, ...] = SEEDS

    def settings(self, net: str) -> tuple[str, ...]:
        return self.sets + (self.coll_sets if net == "coll" else ())


# Ours: column feature, action ×10, lr 0.1 for both, no dropout, best-validation weights of 40 epochs,
# 4 decisions/s. The paper: pooled feature, raw action, Coll-Q-Net lr 0.01, dropout 0.5, the final
# weights of a long training, 10 Hz. Cheapest rungs first: a partial ladder is still a table.
RUNGS = (
    Rung("ours"),
    Rung("action ×1", ("action_scale=1",)),
    Rung("Coll-Q-Net lr 0.01", nets=("coll",), coll_sets=("lr=0.01",)),
    Rung("dropout 0.5", ("dropout=0.5",)),
    Rung("pooled feature", ("trunk=efficientnet_lite0",)),
    Rung("10 Hz", hz=10.0),
    Rung("final weights after 200 epochs", ("epochs=200", "weights=final")),
    Rung("all the paper's settings, 10 Hz", PAPER_SETTINGS, hz=10.0, coll_sets=("lr=0.01",)),
)
# Beyond the paper, one seed each but the label's horizon (their own sections of docs/ablation.md):
# Depth-Q-Net trained on the depth 1 … K steps ahead (docs/design.md#lookahead), to test whether its
# one-step horizon is what holds it back; and the paper-size head, a fixed PCA of the feature to 256
# numbers (the paper's 257 → 4096 first layer; docs/design.md#heads). And the converse of the
# lookahead: Coll-Q-Net's collision label shortened from 5 frames (1.25 s at 4 Hz) to 1 (Depth-Q-Net's
# one step) or 2 (the 0.5 s its 5 frames span at 10 Hz), to test whether its far label carries it.
BEYOND = (
    Rung("Depth-Q-Net lookahead 3", ("lookahead=3",), nets=("depth",), seeds=(0,)),
    Rung("Depth-Q-Net lookahead 5", ("lookahead=5",), nets=("depth",), seeds=(0,)),
    Rung("Depth-Q-Net lookahead 5, 10 Hz", ("lookahead=5",), nets=("depth",), hz=10.0, seeds=(0,)),
    Rung("paper-size head (PCA to 256)", ("feature_projection=256",), seeds=(0,)),
    Rung("Coll-Q-Net label 1 frame (0.25 s)", ("samples.horizon=1",), nets=("coll",)),
    Rung("Coll-Q-Net label 2 frames (0.5 s)", ("samples.horizon=2",), nets=("coll",)),
)


@dataclass(frozen=True)
class Ladder:
    """A canyon family's ladder: its preset (dataset, run length), its `val` canyons, rungs, training
    sizes and seeds. The hard family's goal is its canyons' end: its distance is to the first collision."""

    family: str
    preset: str
    canyons: str
    rungs: tuple[Rung, ...]
    beyond: tuple[Rung, ...] = ()
    sizes: tuple[int, ...] = SIZES
    seeds: tuple[int, ...] = SEEDS

    @property
    def distance(self) -> str:
        return "to first collision (m)" if self.family == "hard" else "distance (m)"


# The paper's canyons: only the rungs docs/val_choices.md has no row for, beside ours for reference.
PAPER_RUNGS = ("ours", "dropout 0.5", "10 Hz", "final weights after 200 epochs")
LADDERS = {
    "hard": Ladder("hard", "hard", "hard/val:1000-1019", RUNGS, BEYOND),
    "paper": Ladder("paper", "paper", "val:1000-1019", tuple(r for r in RUNGS if r.name in PAPER_RUNGS)),
}


def folder(out: Path, rung: Rung) -> Path:
    """A rung's sweep folder: one per decision rate (another rate is another dataset)."""
    return out / f"{rung.hz:g}hz"


def sweep_of(ladder: Ladder, rung: Rung, net: str, seeds: tuple[int, ...] | None = None) -> Sweep:
    """A rung's sweep of one network (`depthq sweep --preset … --set …`), at `seeds` (the rung's)."""
    grid = tuple(parse_setting(s) for s in rung.settings(net))
    return widened(retarget(get_preset(ladder.preset), None, ladder.canyons, rung.hz), runs=max(ladder.sizes),
                   name=f"{ladder.preset} sweep", subsets=ladder.sizes, seeds=seeds or rung.seeds,
                   nets=(net,), grid=grid)


def run(ladder: Ladder, out: Path) -> int:
    """Every rung's sweeps, seed-major, then the table of what finished."""
    for seed in ladder.seeds:
        for rung in ladder.rungs + ladder.beyond:
            if seed not in rung.seeds:
                continue
            for net in rung.nets:
                sweep = sweep_of(ladder, rung, net, (seed,))
                print(f"{sweep.name} into {folder(out, rung)}: {net}, seed {seed}, {rung.name}", flush=True)
                run_sweep(sweep, folder(out, rung), finish=build_report)
    return table(ladder, out)


def _metrics(root: Path, name: str, hard: bool) -> dict[str, float] | None:
    summary = root / "eval" / name / "summary.json"
    if not summary.is_file():
        return None
    s = read_json(summary)["summary"]
    # The acting weights' record (best.json, last.json or average.json); an old record's `select` too.
    stem = weights_stem(chosen_weights(read_config(root / "models" / name), None))
    weights = read_sidecar(root / "models" / name, stem)
    return {
        "successes": s["successes"],
        "distance": s["distance_to_collision_mean"] if hard else s["distance_mean"],
        "closest": s["closest_mean"],
        "val_loss": weights["val_loss"],
    }


def results(ladder: Ladder, out: Path, rungs: tuple[Rung, ...]) -> list[dict[str, Any]]:
    """Per rung, network and size, the metrics of each seed's model that has been driven."""
    rows = []
    for rung in rungs:
        for net in rung.nets:
            sweep = sweep_of(ladder, rung, net)
            for n in ladder.sizes:
                hard = ladder.family == "hard"
                cells = [m for model in sweep.models() if model.runs == n
                         if (m := _metrics(folder(out, rung), model.name, hard)) is not None]
                rows.append({"rung": rung.name, "net": net, "runs": n, "cells": cells,
                             "seeds": len(rung.seeds)})
    return rows


def _markdown(rows: list[dict[str, Any]], distance: str) -> list[str]:
    """The rows with at least one driven model, then a line naming those with none yet."""
    lines = [f"| rung | network | runs | successes / 20 | {distance} | closest (m) | val loss |",
             "|---|---|---|---|---|---|---|"]
    for row in (row for row in rows if row["cells"]):
        net = {"depth": "Depth-Q-Net", "coll": "Coll-Q-Net"}[row["net"]]
        values = {k: [c[k] for c in row["cells"]] for k in ("successes", "distance", "closest", "val_loss")}
        formats = {"successes": ".1f", "distance": ".2f", "closest": ".2f", "val_loss": ".4f"}
        cell = {k: mean_interval(values[k], fmt, row["seeds"]) for k, fmt in formats.items()}
        lines.append(f"| {row['rung']} | {net} | {row['runs']} | {cell['successes']} | {cell['distance']} | "
                     f"{cell['closest']} | {cell['val_loss']} |")
    if missing := [f"{row['rung']} ({row['net']}, {row['runs']} runs)" for row in rows if not row["cells"]]:
        lines += ["", "Not driven in this folder yet: " + "; ".join(missing) + "."]
    return lines


def table(ladder: Ladder, out: Path) -> int:
    """OUT/ablation.md and ablation.png (and horizon.png with rungs beyond the paper) of what finished."""
    distance = ladder.distance
    rows = results(ladder, out, ladder.rungs)
    seeds = ", ".join(map(str, ladder.seeds))
    text = (f"Mean over seeds {seeds} [95 % Student-t interval]; {ladder.canyons}, "
            f"`python -m depthq.experiments.ablation run {ladder.family} OUT`.\n\n"
            + "\n".join(_markdown(rows, distance)) + "\n")
    if ladder.beyond:
        beyond = results(ladder, out, ladder.beyond)
        text += ("\nBeyond the paper, seed 0, and seeds 0 and 1 where a cell has an interval (the "
                 "lookahead's 3 seeds are in the `eval` canyons):\n\n"
                 + "\n".join(_markdown(beyond, distance)) + "\n")
        _horizon_figure(rows + beyond, ladder, out / "horizon.png")
    (out / "ablation.md").write_text(text)
    _figure(rows, ladder, out / "ablation.png")
    print(text)
    return 0


# The setting that says how far each network's training signal looks ahead, in frames, and its default.
HORIZON_SETTING = {"depth": ("lookahead", 1), "coll": ("samples.horizon", HORIZON)}


def _looks_ahead(rung: Rung, net: str) -> float | None:
    """Seconds ahead that `net`'s training signal looks in `rung`, for the rungs at 4 Hz that change
    nothing but that (ours, the lookahead, the label's horizon); None for the others."""
    key, frames = HORIZON_SETTING[net]
    settings = dict(setting.split("=", 1) for setting in rung.settings(net))
    if rung.hz != Rung.hz or set(settings) - {key}:
        return None
    return int(settings.get(key, frames)) / rung.hz


def _horizon_figure(rows: list[dict[str, Any]], ladder: Ladder, path: Path) -> None:
    """Distance to the first collision against how far the training signal looks ahead: one line per
    (network, size) through the seeds' means, each seed a dot."""
    by_name = {rung.name: rung for rung in ladder.rungs + ladder.beyond}
    sizes = ladder.sizes
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for net, n in ((net, n) for net in ("depth", "coll") for n in sizes):
        points = [(ahead, [c["distance"] for c in row["cells"]]) for row in rows
                  if row["net"] == net and row["runs"] == n and row["cells"]
                  if (ahead := _looks_ahead(by_name[row["rung"]], net)) is not None]
        if not points:
            continue
        points.sort()
        name = "Depth-Q-Net, depth ahead" if net == "depth" else "Coll-Q-Net, collision label"
        ax.plot([x for x, _ in points], [np.mean(v) for _, v in points], "o-" if n == max(sizes) else "s--",
                color="C0" if net == "depth" else "C3", alpha=0.5 + 0.5 * (n == max(sizes)),
                label=f"{name}, {n} runs")
        for x, values in points:
            ax.plot([x] * len(values), values, "k.", ms=4)
    ax.set_xlabel("how far the training signal looks ahead (s, at 4 Hz)")
    ax.set_ylabel("to first collision (m)")
    ax.set_title(f"Value horizon, {ladder.canyons}; dots: seeds", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _figure(rows: list[dict[str, Any]], ladder: Ladder, path: Path) -> None:
    """Per rung, successes and the distance metric: one bar per (network, size) at the seeds' mean,
    each seed a dot (the distance does not saturate where successes are all 0 or all 20)."""
    groups = [(net, n) for net in ("depth", "coll") for n in ladder.sizes]
    rungs, distance = ladder.rungs, ladder.distance
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    width = 0.8 / len(groups)
    for ax, key, label in ((axes[0], "successes", "successes / 20"), (axes[1], "distance", distance)):
        for g, (net, n) in enumerate(groups):
            name = f"{'DQN' if net == 'depth' else 'CQN'} {n} runs"
            for r, rung in enumerate(rungs):
                cells = next((row["cells"] for row in rows
                              if row["rung"] == rung.name and row["net"] == net and row["runs"] == n), [])
                if not cells:
                    continue
                x = r + (g - (len(groups) - 1) / 2) * width
                values = [c[key] for c in cells]
                ax.bar(x, np.mean(values), width, color=f"C{g}", alpha=0.6, label=name)
                name = None  # one legend entry per group, at its first drawn bar
                ax.plot([x] * len(values), values, "k.", ms=4)
        ax.set_ylabel(label)
    axes[0].set_ylim(0, 20.5)
    axes[0].legend(fontsize=8, ncols=4, loc="upper right")
    axes[0].set_title(f"Ablation ladder, {ladder.family} canyons ({ladder.canyons}); dots: seeds")
    axes[1].set_xticks(range(len(rungs)), [rung.name for rung in rungs], rotation=20, ha="right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m depthq.experiments.ablation",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("action", choices=("run", "table"),
                        help="run: run (or resume) every rung's sweep, then table; table: what finished")
    parser.add_argument("family", choices=tuple(LADDERS), help="the canyon family whose ladder to climb")
    parser.add_argument("out", type=Path, help="the ladder's folder (a sweep per decision rate inside)")
    args = parser.parse_args(argv)
    ladder = LADDERS[args.family]
    work = run if args.action == "run" else table
    return guarded(f"python -m depthq.experiments.ablation {args.action}", lambda: work(ladder, args.out))


if __name__ == "__main__":
    sys.exit(main())
