"""The ablation ladder (docs/ablation.md): from our defaults to the paper's settings, one factor at a
time and all together, both networks, 200 and 500 runs, seeds 0 and 1, in `val` canyons only; then
the rungs beyond the paper (seed 0; the label's horizon seeds 0 and 1).

    python docs/ablation.py run hard runs/ladder-hard      # runs (or resumes) every rung's sweep
    python docs/ablation.py table hard runs/ladder-hard    # ablation.md, ablation.png of what finished
    python docs/ablation.py run paper runs/ladder-paper    # paper canyons: rows docs/val_choices.md lacks

Every rung is a `depthq sweep` into OUT/4hz (or OUT/10hz: another rate is another dataset), so an
interrupted ladder resumes with the same command and a rung shared with another ladder is reused.
Rungs run seed 0 first, so a partial ladder already has a whole column of rungs.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.cli import main as depthq
from depthq.configio import read_json
from depthq.data.labels import HORIZON
from depthq.report.presets import get_preset
from depthq.report.sweep import Sweep, parse_setting, retarget
from depthq.report.tables import interval

SIZES, SEEDS = (200, 500), (0, 1)
PAPER_SETTINGS = ("action_scale=1", "dropout=0.5", "trunk=efficientnet_lite0", "epochs=200", "select=final")


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
    Rung("final weights after 200 epochs", ("epochs=200", "select=final")),
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
    Rung("Coll-Q-Net label 1 frame (0.25 s)", ("horizon=1",), nets=("coll",)),
    Rung("Coll-Q-Net label 2 frames (0.5 s)", ("horizon=2",), nets=("coll",)),
)


@dataclass(frozen=True)
class Ladder:
    """A canyon family's ladder: its preset (dataset, run length), its `val` canyons and rungs."""

    preset: str
    canyons: str
    rungs: tuple[Rung, ...]
    beyond: tuple[Rung, ...] = ()


# The paper's canyons: only the rungs docs/val_choices.md has no row for, beside ours for reference.
PAPER_RUNGS = ("ours", "dropout 0.5", "10 Hz", "final weights after 200 epochs")
LADDERS = {
    "hard": Ladder("hard", "hard/val:1000-1019", RUNGS, BEYOND),
    "paper": Ladder("paper", "val:1000-1019", tuple(r for r in RUNGS if r.name in PAPER_RUNGS)),
}


def folder(out: Path, rung: Rung) -> Path:
    return out / f"{rung.hz:g}hz"


def sweep_args(family: str, rung: Rung, net: str, seeds: tuple[int, ...], out: Path) -> list[str]:
    preset, canyons = LADDERS[family].preset, LADDERS[family].canyons
    args = ["sweep", "--preset", preset, "--canyons", canyons, "--runs", str(max(SIZES)),
            "--sizes", ",".join(map(str, SIZES)),
            "--seeds", ",".join(map(str, seeds)), "--nets", net, "--hz", f"{rung.hz:g}",
            "--out", str(folder(out, rung))]
    for setting in rung.settings(net):
        args += ["--set", setting]
    return args


def sweep_of(family: str, rung: Rung, net: str) -> Sweep:
    """The Sweep that `sweep_args` runs, to find its models' folders."""
    ladder = LADDERS[family]
    grid = tuple(parse_setting(s) for s in rung.settings(net))
    return replace(retarget(get_preset(ladder.preset), None, ladder.canyons, rung.hz),
                   runs=max(SIZES), subsets=SIZES, seeds=rung.seeds, nets=(net,), grid=grid)


def run(family: str, out: Path) -> int:
    ladder = LADDERS[family]
    for seed in SEEDS:
        for rung in ladder.rungs + ladder.beyond:
            if seed not in rung.seeds:
                continue
            for net in rung.nets:
                args = sweep_args(family, rung, net, (seed,), out)
                print("depthq " + " ".join(args), flush=True)
                if (status := depthq(args)) != 0:
                    return status
    return table(family, out)


def _metrics(root: Path, name: str, hard: bool) -> dict[str, float] | None:
    summary = root / "eval" / name / "summary.json"
    if not summary.is_file():
        return None
    s = read_json(summary)["summary"]
    config = read_json(root / "models" / name / "config.json")
    which = config.get("train", {}).get("select", "best")
    weights = read_json(root / "models" / name / ("last.json" if which == "final" else "best.json"))
    return {
        "successes": s["successes"],
        "distance": s["distance_to_collision_mean"] if hard else s["distance_mean"],
        "closest": s["closest_mean"],
        "val_loss": weights["val_loss"],
    }


def _cell(values: list[float], fmt: str, seeds: int) -> str:
    text = f"{np.mean(values):{fmt}}"
    if (ci := interval(values)) is not None:
        text += f" [{ci[0]:{fmt}}, {ci[1]:{fmt}}]"
    return text + ("" if len(values) == seeds else f" ({len(values)} of {seeds} seeds)")


def results(family: str, out: Path, rungs: tuple[Rung, ...]) -> list[dict[str, Any]]:
    rows = []
    for rung in rungs:
        for net in rung.nets:
            sweep = sweep_of(family, rung, net)
            for n in SIZES:
                cells = [m for model in sweep.models() if model.runs == n
                         if (m := _metrics(folder(out, rung), model.name, family == "hard")) is not None]
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
        cell = {k: _cell(values[k], fmt, row["seeds"]) for k, fmt in formats.items()}
        lines.append(f"| {row['rung']} | {net} | {row['runs']} | {cell['successes']} | {cell['distance']} | "
                     f"{cell['closest']} | {cell['val_loss']} |")
    if missing := [f"{row['rung']} ({row['net']}, {row['runs']} runs)" for row in rows if not row["cells"]]:
        lines += ["", "Not driven in this folder yet: " + "; ".join(missing) + "."]
    return lines


def table(family: str, out: Path) -> int:
    ladder = LADDERS[family]
    distance = "to first collision (m)" if family == "hard" else "distance (m)"
    rows = results(family, out, ladder.rungs)
    text = (f"Mean over seeds {', '.join(map(str, SEEDS))} [95 % Student-t interval]; {ladder.canyons}, "
            f"`python docs/ablation.py run {family} OUT`.\n\n" + "\n".join(_markdown(rows, distance)) + "\n")
    if ladder.beyond:
        beyond = results(family, out, ladder.beyond)
        text += ("\nBeyond the paper, seed 0, and seeds 0 and 1 where a cell has an interval (the "
                 "lookahead's 3 seeds are in the `eval` canyons):\n\n"
                 + "\n".join(_markdown(beyond, distance)) + "\n")
        _horizon_figure(rows + beyond, ladder.rungs + ladder.beyond, out / "horizon.png", ladder.canyons)
    (out / "ablation.md").write_text(text)
    _figure(rows, ladder.rungs, out / "ablation.png", family)
    print(text)
    return 0


# The setting that says how far each network's training signal looks ahead, in frames, and its default.
HORIZON_SETTING = {"depth": ("lookahead", 1), "coll": ("horizon", HORIZON)}


def _looks_ahead(rung: Rung, net: str) -> float | None:
    """Seconds ahead that `net`'s training signal looks in `rung`, for the rungs at 4 Hz that change
    nothing but that (ours, the lookahead, the label's horizon); None for the others."""
    key, frames = HORIZON_SETTING[net]
    settings = dict(setting.split("=", 1) for setting in rung.settings(net))
    if rung.hz != Rung.hz or set(settings) - {key}:
        return None
    return int(settings.get(key, frames)) / rung.hz


def _horizon_figure(rows: list[dict[str, Any]], rungs: tuple[Rung, ...], path: Path, canyons: str) -> None:
    """Distance to the first collision against how far the training signal looks ahead: one line per
    (network, size) through the seeds' means, each seed a dot."""
    by_name = {rung.name: rung for rung in rungs}
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for net, n in ((net, n) for net in ("depth", "coll") for n in SIZES):
        points = [(ahead, [c["distance"] for c in row["cells"]]) for row in rows
                  if row["net"] == net and row["runs"] == n and row["cells"]
                  if (ahead := _looks_ahead(by_name[row["rung"]], net)) is not None]
        if not points:
            continue
        points.sort()
        name = "Depth-Q-Net, depth ahead" if net == "depth" else "Coll-Q-Net, collision label"
        ax.plot([x for x, _ in points], [np.mean(v) for _, v in points], "o-" if n == max(SIZES) else "s--",
                color="C0" if net == "depth" else "C3", alpha=0.5 + 0.5 * (n == max(SIZES)),
                label=f"{name}, {n} runs")
        for x, values in points:
            ax.plot([x] * len(values), values, "k.", ms=4)
    ax.set_xlabel("how far the training signal looks ahead (s, at 4 Hz)")
    ax.set_ylabel("to first collision (m)")
    ax.set_title(f"Value horizon, {canyons}; dots: seeds", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _figure(rows: list[dict[str, Any]], rungs: tuple[Rung, ...], path: Path, family: str) -> None:
    """Per rung, successes and the distance metric: one bar per (network, size) at the seeds' mean,
    each seed a dot (the distance does not saturate where successes are all 0 or all 20)."""
    groups = [(net, n) for net in ("depth", "coll") for n in SIZES]
    distance = "to first collision (m)" if family == "hard" else "distance (m)"
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
    axes[0].set_title(f"Ablation ladder, {family} canyons ({LADDERS[family].canyons}); dots: seeds")
    axes[1].set_xticks(range(len(rungs)), [rung.name for rung in rungs], rotation=20, ha="right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) != 4 or sys.argv[1] not in ("run", "table") or sys.argv[2] not in LADDERS:
        sys.exit(__doc__)
    verb, family, out = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    sys.exit(run(family, out) if verb == "run" else table(family, out))
