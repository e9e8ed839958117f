"""Fig. 5 (convergence) and the success-rate-vs-data plot, from checkpoint logs and evaluations."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.checkpoint import METRICS, read_metrics
from depthq.networks import get_network, network_names
from depthq.pipeline.sweep import Sweep, variant_label
from depthq.report.tables import collect_results, interval, per_seed


def plot_fig5(out: Path, sweep: Sweep, path: Path) -> None:
    """Training and validation loss per epoch for each subset size (top), and the standard deviation
    of the per-sample validation loss over a batch (bottom: the paper's over-fitting signal), each
    averaged over seeds, for the sweep's first variant. The spread gets its own row: drawn as bands,
    six sizes hide each other."""
    fig, axes = plt.subplots(2, len(sweep.nets), figsize=(6 * len(sweep.nets), 7), sharex=True, squeeze=False)
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(sweep.subsets)))
    first = sweep.variants()[0]
    folders = {(m.net, m.runs, m.seed): m.name for m in sweep.models() if m.variant == first}
    for column, net in enumerate(sweep.nets):
        loss_ax, std_ax = axes[0, column], axes[1, column]
        for colour, n in zip(colours, sweep.subsets, strict=True):
            logs = [
                read_metrics(p)
                for s in sweep.seeds
                if ((p := out / "models" / folders[net, n, s]) / METRICS).is_file()
            ]
            logs = [m for m in logs if m]
            if not logs:
                continue
            e = min(len(m["epoch"]) for m in logs)
            epoch = logs[0]["epoch"][:e]
            train = np.mean([m["train_loss"][:e] for m in logs], axis=0)
            val = np.mean([m["val_loss"][:e] for m in logs], axis=0)
            std = np.mean([m["val_loss_std"][:e] for m in logs], axis=0)
            loss_ax.plot(epoch, train, "--", color=colour, lw=1, label=f"{n} runs, train")
            loss_ax.plot(epoch, val, "-", color=colour, lw=1.5, label=f"{n} runs, validation")
            std_ax.plot(epoch, std, "-", color=colour, lw=1.5, label=f"{n} runs")
        network = get_network(net)
        variant = f" ({variant_label(first)})" if first else ""
        loss_ax.set_title(f"{network.label}: {network.loss_title}{variant}")
        loss_ax.set_ylabel("loss")
        if loss_ax.lines:  # none when no model of this network has a training log yet
            loss_ax.legend(fontsize=7, ncol=2)
        std_ax.set_title(f"{network.label}: std of the validation loss over a batch")
        std_ax.set_xlabel("epoch (100 training batches of 64)")
        std_ax.set_ylabel("std")
        if std_ax.lines:
            std_ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_success_vs_runs(out: Path, sweep: Sweep, path: Path) -> None:
    """The paper's claim at a glance: successes out of the evaluation canyons against training runs,
    mean over seeds with its 95 % interval, one line per network and variant."""
    results = collect_results(out, sweep)
    variants = sweep.variants()
    nets = [net for net in network_names() if net in sweep.nets]
    lines = [(net, k, variant) for net in nets for k, variant in enumerate(variants)]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for line, (net, k, variant) in enumerate(lines):
        shift = 1 + 0.025 * (line - (len(lines) - 1) / 2)  # side by side: the bars do not hide each other
        xs, mean, low, high = [], [], [], []
        for n in sweep.subsets:
            succ = [r["summary"]["successes"] for r in per_seed(results, net, n, variant)]
            if succ:
                ci = interval(succ) or (np.mean(succ), np.mean(succ))
                xs.append(n * shift)
                mean.append(np.mean(succ))
                low.append(np.mean(succ) - ci[0])
                high.append(ci[1] - np.mean(succ))
        if xs:
            label = get_network(net).label + (f", {variant_label(variant)}" if variant else "")
            colour = get_network(net).colour
            ax.errorbar(xs, mean, yerr=[low, high], fmt="osv^DP"[k % 6] + "-", capsize=3, color=colour,
                        alpha=1.0 - 0.5 * k / len(variants), label=label)
    for net in sweep.nets:
        network = get_network(net)
        paper = [(n, network.paper[n][1]) for n in sweep.subsets if n in network.paper]
        if paper:
            label = f"{network.label}, paper"
            ax.plot(*zip(*paper, strict=True), "--", color=network.colour, alpha=0.6, label=label)
    seeds = len(sweep.seeds)
    ax.set_title(f"mean over {seeds} seeds, bars: 95 % interval" if seeds > 1 else "one seed")
    canyons = max((r["summary"]["runs"] for r in results.values()), default=20)
    ax.set_ylim(-0.5, canyons + 0.5)
    ax.set_xlabel("training runs")
    ax.set_ylabel(f"successes out of {canyons} (distance > 15 m)")
    ax.set_xscale("log")
    ax.set_xticks(list(sweep.subsets), [str(n) for n in sweep.subsets])
    ax.minorticks_off()  # the sizes themselves, not 4×10¹ …
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
