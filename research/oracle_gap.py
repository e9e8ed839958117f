"""The oracle gap (docs/oracle_gap.md): Depth-Q-Net candidates, one factor at a time, against
Coll-Q-Net, in the hard family's `val` canyons; and each model's agreement with the one-step oracle
along its own runs.

    python -m research.oracle_gap run OUT [--seeds 0,1] [--sizes 500] [--only TEXT]
    python -m research.oracle_gap table OUT [--seeds 0,1] [--sizes 500] [--only TEXT]
    python -m research.oracle_gap predicts OUT [--figure PATH]
    python -m research.oracle_gap where OUT [--figure PATH]
    python -m research.oracle_gap dead MODEL[,MODEL…]

`run` runs (or resumes) one `depthq sweep` per candidate into OUT, all sharing OUT's dataset, then
measures the agreement of every finished evaluation (OUT/agreement.json, kept: an evaluation is
measured once); `table` prints the Markdown table of what has finished; `predicts` how well each of
the diagnostic's measures predicts driving across all of them, `where` which states, actions and
bins each model gets wrong (each with a figure); `dead` which bins a checkpoint predicts as 0 always.
The `eval` canyons are never driven here. The paired comparison of both networks in a sweep folder
is `python -m depthq.report.paired`.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/oracle_gap.md came from the code of commit 0471132 (2026-11-26: the last change of that page's
tables).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.configio import read_json, write_json
from depthq.control.action_selection import ACTIONS
from depthq.errors import ConfigError, guarded
from depthq.evaluate.oracle import Oracle
from depthq.evaluate.probe import agreement_file, measure_agreement
from depthq.networks import get_network
from depthq.pipeline.presets import get_preset
from depthq.pipeline.runner import run_sweep
from depthq.pipeline.sweep import (
    Sweep,
    parse_ints,
    parse_setting,
    retarget,
    widened,
)
from depthq.report.build import build_report
from depthq.report.cells import mean_interval, ranks_driving
from depthq.train.dead_outputs import count_dead_outputs, dead_outputs


@dataclass(frozen=True)
class Candidate:
    """A row: a network and the training settings (`depthq sweep --set`) it changes from the defaults."""

    name: str
    sets: tuple[str, ...] = ()
    net: str = "depth"


def paper_head(name: str, *sets: str) -> Candidate:
    """A candidate on the paper's head (the image feature and the action into one MLP). Each such row
    names the head: the depth-first head has been `--model depth`'s default since this ladder picked
    it, and the rows must keep meaning what they measured."""
    return Candidate(name, ("depth.head_form=concat", *sets))


def final_weights(name: str, *sets: str) -> Candidate:
    """A depth-first candidate acting with its final weights, as the depth-first head did until the
    weight average became its default (docs/oracle_gap.md#weight-average): such rows name it, to keep
    meaning what they measured."""
    return Candidate(name, ("average=0", *sets))


CANDIDATES = (
    Candidate("Coll-Q-Net, for scale", net="coll"),
    paper_head("Depth-Q-Net, the paper's head"),
    paper_head("keep the samples before each run's end (horizon 1)", "samples.horizon=1"),
    paper_head("head width 1024", "hidden=1024"),
    Candidate("per-action head (scene and action apart)", ("depth.head_form=per_action",)),
    paper_head("4 × 4 grid feature, head width 1024", "trunk=efficientnet_lite0_grid", "hidden=1024"),
    paper_head("relative depth loss", "depth.depth_loss=relative"),
    paper_head("bootstrapped value, γ = 0.5", "depth.bootstrap=0.5"),
    paper_head("bootstrapped value, γ = 0.9", "depth.bootstrap=0.9"),
    paper_head("bootstrapped value, γ = 0.95", "depth.bootstrap=0.95"),
    paper_head("bootstrapped value, γ = 0.98", "depth.bootstrap=0.98"),
    paper_head("bootstrapped value γ = 0.9, relative loss", "depth.bootstrap=0.9",
               "depth.depth_loss=relative"),
    paper_head("mirrored samples", "mirror=true"),
    paper_head("mirrored samples, bootstrapped value γ = 0.9", "mirror=true", "depth.bootstrap=0.9"),
    Candidate("Coll-Q-Net, mirrored samples", ("mirror=true",), net="coll"),
    final_weights("depth-first head (perception, then dynamics), final weights"),
    final_weights("depth-first head, output bias 1 m (no dead bins)", "depth.output_bias=1.0"),
    final_weights("depth-first head, width 1024", "hidden=1024"),
    Candidate("depth-first head, mean of the last quarter's weights (the default)"),
)


@dataclass(frozen=True)
class Setup:
    """Where the candidates run: a preset's dataset, its `val` canyons, the sizes and seeds."""

    preset: str = "hard"
    canyons: str | None = "hard/val:1000-1019"  # None: the preset's own
    runs: int = 500
    sizes: tuple[int, ...] = (500,)
    seeds: tuple[int, ...] = (0,)


def sweep_of(setup: Setup, candidate: Candidate, seeds: tuple[int, ...] | None = None) -> Sweep:
    """A candidate's sweep (`depthq sweep --preset … --nets … --set …`), at `seeds` (the setup's)."""
    return widened(
        retarget(get_preset(setup.preset), None, setup.canyons),
        runs=setup.runs,
        name=f"{setup.preset} sweep",
        subsets=setup.sizes,
        seeds=seeds or setup.seeds,
        nets=(candidate.net,),
        grid=tuple(parse_setting(s) for s in candidate.sets),
    )


def model_names(setup: Setup, candidate: Candidate, size: int) -> list[str]:
    """The model folders a candidate's sweeps train at `size`, one per seed."""
    return [m.name for m in sweep_of(setup, candidate).models() if m.runs == size]


def run(out: Path, setup: Setup, candidates: tuple[Candidate, ...] = CANDIDATES) -> int:
    """Every candidate's sweeps (seed-major, so a partial run has whole columns), each evaluation's
    agreement measured as soon as it exists (an interrupted run keeps what it measured)."""
    for seed in setup.seeds:
        for candidate in candidates:
            print(f"{out}: {candidate.name}, seed {seed}", flush=True)
            run_sweep(sweep_of(setup, candidate, (seed,)), out, finish=build_report)
            measure(out, setup, (candidate,))
    print(table(out, setup, candidates))
    return 0


def measure(out: Path, setup: Setup, candidates: tuple[Candidate, ...] = CANDIDATES) -> dict[str, Any]:
    """The one-step oracle's agreement with every finished evaluation, with re-predicted values:
    OUT/agreement.json, each evaluation measured once."""
    path = out / "agreement.json"
    done: dict[str, Any] = read_json(path) if path.is_file() else {}
    for candidate in candidates:
        for size in setup.sizes:
            for name in model_names(setup, candidate, size):
                folder = out / "eval" / name
                if name not in done and (folder / "summary.json").is_file():
                    measured = measure_agreement(folder, Oracle(), out / "probe", predictions=True)
                    # merged with the file as it is now: another candidate's run may have written it
                    done = {**(read_json(path) if path.is_file() else {}), **done, name: measured}
                    write_json(path, done)
    return done


def table(out: Path, setup: Setup, candidates: tuple[Candidate, ...] = CANDIDATES) -> str:
    """Markdown: per candidate and size, distance to the first collision (mean over seeds, 95 %
    interval with 2 or more), ends reached, agreement with the one-step oracle on decisive steps and
    in the last 2 s before a collision, pillar collisions, decisions a new pixel noise keeps."""
    agreement = read_json(out / "agreement.json") if (out / "agreement.json").is_file() else {}
    lines = [
        "| candidate | runs | seeds | to first collision (m) | ends reached /20 | agrees, decisive | "
        "agrees, last 2 s | pillar collisions | same decision, new noise |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for candidate in candidates:
        for size in setup.sizes:
            rows = []
            for name in model_names(setup, candidate, size):
                summary = out / "eval" / name / "summary.json"
                if summary.is_file():
                    rows.append((json.loads(summary.read_text())["summary"], agreement.get(name)))
            if not rows:
                continue
            d2c = [s["distance_to_collision_mean"] for s, _ in rows]
            agreed = [a for _, a in rows if a]

            def mean(key: str, fmt: str, agreed: list = agreed) -> str:
                values = [a[key] for a in agreed if a.get(key) is not None]
                return format(sum(values) / len(values), fmt) if values else "–"

            pillars = (
                f"{sum(a['collisions_with_pillar'] for a in agreed)}/{sum(a['collisions'] for a in agreed)}"
                if agreed
                else "–"
            )
            ends = sum(s["reached_end"] for s, _ in rows) / len(rows)
            cells = [candidate.name, size, len(rows), mean_interval(d2c, ".2f"), f"{ends:.1f}",
                     mean("agreement_decisive", ".0%"), mean("agreement_before_collision", ".0%"), pillars,
                     mean("same_decision_new_noise", ".0%")]
            lines.append("| " + " | ".join(map(str, cells)) + " |")
    return "\n".join(lines)


# What the on-policy diagnostic measures of a model (`depthq probe --parts agreement --predictions`).
DIAGNOSTICS = (
    ("agrees with the oracle, all steps", "agreement"),
    ("agrees, decisive steps", "agreement_decisive"),
    ("agrees, last 2 s before a collision", "agreement_before_collision"),
    ("same decision under new pixel noise", "same_decision_new_noise"),
    ("candidates' score error (m)", "score_error"),
    ("candidates' predicted spread (m)", "predicted_spread"),
    ("pillar share of the collisions", "pillar_share"),
)


def _diagnostics(out: Path) -> dict[str, dict[str, Any]]:
    """Every measured model's diagnostics (OUT/agreement.json), with its pillar share of collisions."""
    measured = read_json(out / "agreement.json") if (out / "agreement.json").is_file() else {}
    for m in measured.values():
        m["pillar_share"] = m["collisions_with_pillar"] / m["collisions"] if m["collisions"] else None
    return measured


def predicts(out: Path) -> str:
    """Markdown: how well each diagnostic predicts a model's distance to the first collision, across
    every model measured in OUT (each model-seed one point): Spearman's rank correlation."""
    measured = _diagnostics(out)
    lines = ["| diagnostic | models | Spearman ρ with distance to first collision | p |", "|---|---|---|---|"]
    lines += [ranks_driving(label, list(measured.values()), key) for label, key in DIAGNOSTICS]
    return "\n".join(lines)


def plot_predicts(out: Path, path: Path) -> None:
    """Each diagnostic against distance to the first collision, one point per measured model."""
    measured = _diagnostics(out)
    fig, axes = plt.subplots(2, 4, figsize=(15, 6.5), sharey=True)
    for ax, (label, key) in zip(axes.flat, DIAGNOSTICS, strict=False):
        for name, m in measured.items():
            if m.get(key) is None:
                continue
            ax.scatter(m[key], m["distance_to_collision_mean"],
                       c="tab:red" if name.startswith("coll") else "tab:blue",
                       marker="s" if _depth_first(name) else "o")
        ax.set_xlabel(label, fontsize=9)
    for ax in axes[:, 0]:
        ax.set_ylabel("to first collision (m)")
    axes.flat[-1].axis("off")
    axes.flat[-1].legend(handles=[
        plt.Line2D([], [], ls="", marker="o", c="tab:red", label="Coll-Q-Net"),
        plt.Line2D([], [], ls="", marker="o", c="tab:blue", label="Depth-Q-Net candidates"),
        plt.Line2D([], [], ls="", marker="s", c="tab:blue", label="Depth-Q-Net, depth-first head"),
    ], loc="center")
    fig.suptitle("The on-policy diagnostic against driving, one point per model (hard val canyons)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


ROOM_BANDS = (0.0, 0.3, 0.6, 1.0, np.inf)  # the best action's nearest bin one frame ahead (m)
MISTAKES = ("turned the wrong way", "straight where the oracle turned",
            "turned where the oracle went straight")


def _band_labels() -> list[str]:
    return [f"{lo:g}–{hi:g} m" if np.isfinite(hi) else f"≥ {lo:g} m" for lo, hi in pairwise(ROOM_BANDS)]


def _steps(out: Path, name: str) -> dict[str, np.ndarray] | None:
    path = agreement_file(out / "probe", name, Oracle(), ".npz")
    return dict(np.load(path)) if path.is_file() else None


def where_it_fails(out: Path) -> dict[str, dict[str, Any]]:
    """Per measured model, from its per-step arrays (OUT/probe/agreement): agreement on decisive steps
    by the room the best action leaves (which states), what its disagreements are (which actions),
    and a depth model's error per bin of the next frame's depth (which bins)."""
    results = {}
    for name, m in _diagnostics(out).items():
        if (a := _steps(out, name)) is None:
            continue
        decisive = a["decisive"]
        room = a["scores"].max(axis=1)
        bands = [decisive & (room >= lo) & (room < hi) for lo, hi in pairwise(ROOM_BANDS)]
        taken = np.array(ACTIONS)[np.abs(a["policy"][:, None] - np.array(ACTIONS)).argmin(1)]
        wrong = decisive & ~a["agrees"]
        turned = a["oracle"] != 0
        kinds = [wrong & turned & (taken == -a["oracle"]), wrong & turned & (taken == 0), wrong & ~turned]
        result = {
            "distance": m["distance_to_collision_mean"],
            "agree_by_room": [float(a["agrees"][b].mean()) if b.any() else None for b in bands],
            "steps_by_room": [int(b.sum()) for b in bands],
            "mistakes": [float(k.sum() / max(wrong.sum(), 1)) for k in kinds],
        }
        if "predicted" in a and a["predicted"].ndim == 3:  # a one-step depth model's bins per action
            truth = a["true_bins"][:, :, 0, :]
            valid = truth > 0
            error = np.where(valid, np.abs(a["predicted"] - truth), 0).sum((0, 1)) / valid.sum((0, 1))
            result["bin_error"] = error.tolist()
            result["dead_bins"] = list(dead_outputs(a["predicted"]))
        results[name] = result
    return results


def where(out: Path) -> str:
    """Markdown: `where_it_fails` per model, with its distance to the first collision."""
    bands = _band_labels()
    lines = ["| model | to first collision (m) | " + " | ".join(f"agrees, room {b}" for b in bands)
             + " | " + " | ".join(MISTAKES) + " | bin error, edges / centre (m) | bins always 0 |",
             "|---|---|" + "---|" * (len(bands) + len(MISTAKES) + 2)]
    for name, r in where_it_fails(out).items():
        agree = [f"{v:.0%} ({n})" if v is not None else "–"
                 for v, n in zip(r["agree_by_room"], r["steps_by_room"], strict=True)]
        bins = np.array(r.get("bin_error", []))
        error = f"{bins[[0, 1, 24, 25]].mean():.2f} / {bins[11:15].mean():.2f}" if bins.size else "–"
        lines.append(f"| `{name}` | {r['distance']:.2f} | " + " | ".join(agree) + " | "
                     + " | ".join(f"{v:.0%}" for v in r["mistakes"]) + f" | {error} | "
                     + (", ".join(map(str, r["dead_bins"])) or "none" if "dead_bins" in r else "–") + " |")
    return "\n".join(lines)


def _depth_first(name: str) -> bool:
    """Whether a model folder holds the default Depth-Q-Net head (its name sets no head_form)."""
    return name.startswith("depth") and "head_form" not in name


def _short(name: str) -> str:
    """A figure's name of a model: depth_n500_s0_head_formconcat_mirrorTrue → DQN concat mirrorTrue."""
    net, _, rest = name.partition("_")
    rest = "_".join(p for p in rest.split("_") if not (p[:1] in "ns" and p[1:].isdigit()))
    head = "depth-first" if _depth_first(name) else ""
    rest = rest.replace("head_form", "").replace("_", " ")
    return " ".join(filter(None, (get_network(net).label, head, rest)))


def plot_where(out: Path, path: Path) -> None:
    """Three panels over the measured models: the next frame's depth error per bin (depth models),
    agreement on decisive steps by the room the best action leaves, and the kinds of disagreement."""
    results = where_it_fails(out)
    order = sorted(results, key=lambda n: results[n]["distance"])
    colors = dict(zip(order, plt.cm.viridis(np.linspace(0, 0.95, max(len(order), 2))), strict=False))
    fig = plt.figure(figsize=(16, 10))
    grid = fig.add_gridspec(2, 2)
    bins_ax, room_ax = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[0, 1])
    kind_ax = fig.add_subplot(grid[1, :])
    for name in order:
        r, label = results[name], f"{_short(name)} ({results[name]['distance']:.1f} m)"
        if "bin_error" in r:
            bins_ax.plot(r["bin_error"], color=colors[name], label=label)
        room_ax.plot(range(len(r["agree_by_room"])), [np.nan if v is None else v for v in r["agree_by_room"]],
                     "o-", color=colors[name], label=label)
    bins_ax.set(xlabel="bin (0: left edge, +51°; 25: right edge, −52°)",
                ylabel="|predicted − true| next frame (m)", title="which bins: the next frame's depth error")
    room_ax.set(xticks=range(len(ROOM_BANDS) - 1), ylabel="agrees with the one-step oracle, decisive steps",
                title="which states: by the room the best action leaves")
    room_ax.set_xticklabels(_band_labels())
    room_ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    bottom = np.zeros(len(order))
    for kind, share in zip(MISTAKES, np.array([results[n]["mistakes"] for n in order]).T, strict=True):
        kind_ax.barh(range(len(order)), share, left=bottom, label=kind)
        bottom += share
    kind_ax.set(yticks=range(len(order)), xlabel="share of the disagreements on decisive steps",
                title="which actions: how it disagrees with the one-step oracle (models by distance)")
    kind_ax.set_yticklabels([f"{_short(n)} ({results[n]['distance']:.1f} m)" for n in order], fontsize=8)
    kind_ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


DEAD_FRAMES = 3000  # training frames `dead` looks at


def dead_bins(folder: Path, frames: int = DEAD_FRAMES) -> list[int]:
    """The bins a one-step Depth-Q-Net checkpoint predicts as 0 for every candidate action on the
    first `frames` training frames of its own dataset (`count_dead_outputs`; `depthq probe --parts
    dead` looks at the validation frames): bins its policy never sees, whatever the frame."""
    found = count_dead_outputs(Path(folder), split="train", frames=frames)
    return list(found.dead) if found is not None else []


def compare(named: list[tuple[str, Path]]) -> str:
    """Markdown: one row per (name, evaluation folder), e.g. a checkpoint driven with `--weights last`."""
    lines = ["| policy | evaluation | to first collision (m) | ends reached /20 | collisions | successes |",
             "|---|---|---|---|---|---|"]
    for name, folder in named:
        s = json.loads((Path(folder) / "summary.json").read_text())["summary"]
        lines.append(f"| {name} | `{Path(folder).name}` | {s['distance_to_collision_mean']:.2f} | "
                     f"{s['reached_end']} | {s['collisions']} | {s['successes']} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m research.oracle_gap", description=__doc__.split("\n")[0]
    )
    parser.add_argument("action", choices=("run", "table", "predicts", "where", "dead", "compare"))
    parser.add_argument("out", help="the sweep folder the candidates share; compare: NAME=EVAL,NAME=EVAL,…; "
                                    "dead: MODEL,MODEL,…")
    parser.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1")
    parser.add_argument("--sizes", default="500", help="training runs, e.g. 200,500")
    parser.add_argument("--only", default="",
                        help="run, table: only the candidates whose name contains this text")
    parser.add_argument("--figure", type=Path,
                        help="predicts, where: the figure (default OUT/diagnostics.png, OUT/where.png)")
    args = parser.parse_args(argv)
    return guarded(f"python -m research.oracle_gap {args.action}", lambda: _act(args))


def _act(args: argparse.Namespace) -> int:
    if args.action == "dead":
        for folder in args.out.split(","):
            print(f"{folder}: bins predicted 0 for every action on {DEAD_FRAMES} frames: "
                  f"{dead_bins(Path(folder))}")
        return 0
    if args.action == "compare":
        pairs = [item.partition("=") for item in args.out.split(",")]
        print(compare([(name, Path(folder)) for name, _, folder in pairs]))
        return 0
    args.out = Path(args.out)
    setup = Setup(seeds=parse_ints(args.seeds, "--seeds"), sizes=parse_ints(args.sizes, "--sizes"))
    candidates = tuple(c for c in CANDIDATES if args.only in c.name)
    if not candidates:
        raise ConfigError(f"--only {args.only!r}: no candidate's name contains it")
    if args.action == "run":
        return run(args.out, setup, candidates)
    if args.action == "where":
        print(where(args.out))
        plot_where(args.out, args.figure or args.out / "where.png")
        return 0
    if args.action == "predicts":
        print(predicts(args.out))
        plot_predicts(args.out, args.figure or args.out / "diagnostics.png")
        return 0
    print(table(args.out, setup, candidates))
    return 0


if __name__ == "__main__":
    sys.exit(main())
