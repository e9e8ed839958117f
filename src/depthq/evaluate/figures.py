"""Figures of an evaluation: the driven paths in all canyons, and the Fig. 4-style snapshot."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.networks import DepthQNet, ValuePlot, get_network, network_names
from depthq.sim.canyon import CanyonId, generate_canyon
from depthq.sim.sensors import BinConfig
from depthq.sim.topdown import draw_run, plot_runs

ACTION_NAMES = {-1.0: "right (−1)", 0.0: "straight (0)", 1.0: "left (+1)"}
# A policy that is no network's (the heuristic, OU): the true depth alone, drawn as Depth-Q-Net's bins.
DEPTH_PLOT = DepthQNet.plot


def value_plot(policy: dict[str, Any]) -> ValuePlot:
    """How the values of the policy `policy` describes are drawn: its network's way (`Network.plot`)."""
    kind = policy.get("kind")
    return get_network(kind).plot if kind in network_names() else DEPTH_PLOT


def plot_trajectories(runs: list[dict[str, Any]], path: Path, title: str) -> None:
    """Top-down view of every canyon with the path driven in it."""
    items = [(generate_canyon(CanyonId.parse(r["canyon"])), r["poses"]) for r in runs]
    titles = [f"{r['canyon']}\n{r['distance']:.1f} m {'✓' if r['success'] else '✗'}" for r in runs]
    fig = plot_runs(items, titles=titles)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def bin_bearings(config: BinConfig | None = None) -> np.ndarray:
    """Centre bearing (degrees, + = left) of each depth bin, left to right."""
    config = config or BinConfig()
    first = config.first_bearing - (config.group - 1) / 2
    return first - config.group * np.arange(config.n_bins)


def plot_fig4(snaps: list[dict[str, Any]], run: dict[str, Any], policy: dict[str, Any], path: Path) -> None:
    """Per snapshot: the camera frame, the per-action predictions beside the true future depth,
    and the robot's place in the canyon (as Fig. 4 of the paper)."""
    plot = value_plot(policy)
    actions = policy.get("actions", [-1.0, 0.0, 1.0])
    canyon = generate_canyon(CanyonId.parse(run["canyon"]))
    fig, axes = plt.subplots(
        len(snaps),
        3,
        figsize=(12, 3.2 * len(snaps)),
        squeeze=False,
        gridspec_kw={"width_ratios": [1.4, 1.6, 0.6]},
    )
    bearings = bin_bearings()
    for row, snap in zip(axes, snaps, strict=True):
        row[0].imshow(snap["image"])
        row[0].set_title(f"frame t={snap['step']}, action taken {snap['action']:+.0f}", fontsize=8)
        row[0].axis("off")
        if plot.style == "bins":
            row[1].plot(bearings, snap["true_bins"], "r-o", ms=3, label="true depth at t+1 (taken action)")
            for a, pred in zip(actions, snap["values"], strict=True):
                row[1].plot(bearings, pred, "--", label=f"predicted, {ACTION_NAMES.get(a, a)}")
            row[1].invert_xaxis()
            row[1].set_xlabel("bearing (°, left → right)", fontsize=8)
            row[1].set_ylabel(plot.label, fontsize=8)
            row[1].set_ylim(*plot.limits)
            row[1].legend(fontsize=6, loc="lower right")
        else:
            names = [ACTION_NAMES.get(a, str(a)) for a in actions]
            row[1].bar(names, snap["values"], color="tab:purple")
            row[1].set_ylim(*plot.limits)
            row[1].set_ylabel(plot.label, fontsize=8)
        row[1].tick_params(labelsize=7)
        x, y, _ = snap["pose"]
        draw_run(row[2], canyon, run["poses"], span=y + 4)
        row[2].set_ylim(y - 3, y + 4)
        row[2].plot([x], [y], "o", color="tab:blue", ms=7)
    fig.suptitle(f"{policy.get('policy')} in {run['canyon']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_agreement(arrays: dict[str, np.ndarray], summary: dict[str, Any], path: Path) -> None:
    """A policy against an oracle along its own runs (`depthq.evaluate.oracle.agreement`): the share of
    decisive steps where it took the oracle's action, by seconds before the run's collision; and which
    action it took against the oracle's in the last seconds before one."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6), gridspec_kw={"width_ratios": [1.6, 1]})
    hz, decisive, agrees = summary["decision_hz"], arrays["decisive"], arrays["agrees"]
    before = arrays["to_collision_s"]
    steps = np.arange(1, int(4 * hz) + 1) / hz  # the last 4 s, one point per decision
    shares = [agrees[decisive & np.isclose(before, s)].mean() if (decisive & np.isclose(before, s)).any()
              else np.nan for s in steps]
    left.plot(-steps, shares, "o-", label="runs that end in a collision")
    left.axhline(summary["agreement_decisive"], color="k", ls="--", label="all decisive steps")
    left.axhline(1 / 3, color="grey", ls=":", label="chance (3 actions)")
    left.set(xlabel="seconds before the collision", ylabel="takes the oracle's action", ylim=(0, 1),
             title=f"{summary['policy']} vs oracle {summary['oracle']}")
    left.legend(fontsize=8)
    late = before <= 2.0
    actions = (-1.0, 0.0, 1.0)
    counts = np.array([[np.sum(late & np.isclose(arrays["oracle"], o) & np.isclose(arrays["policy"], p))
                        for p in actions] for o in actions])
    right.imshow(counts, cmap="Blues")
    for (i, j), n in np.ndenumerate(counts):
        right.text(j, i, str(n), ha="center", va="center")
    right.set(xticks=range(3), yticks=range(3), xticklabels=actions, yticklabels=actions,
              xlabel="policy's action", ylabel="oracle's action", title="last 2 s before a collision")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
