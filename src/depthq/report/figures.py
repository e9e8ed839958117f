"""Fig. 5 (convergence) and the success-rate-vs-data plot, from checkpoint logs and evaluations."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.report.layout import model_name
from depthq.report.tables import NET_LABELS, PAPER_TABLE1, collect_results


def _read_metrics(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]} if rows else {}


def plot_fig5(out: Path, subsets: tuple[int, ...], seeds: tuple[int, ...], path: Path) -> None:
    """Training and validation loss per epoch for each subset size (top), and the standard deviation
    of the per-sample validation loss over a batch (bottom: the paper's over-fitting signal), each
    averaged over seeds. The spread gets its own row: drawn as bands, six sizes hide each other."""
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex=True)
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(subsets)))
    for column, net in enumerate(("depth", "coll")):
        loss_ax, std_ax = axes[0, column], axes[1, column]
        for colour, n in zip(colours, subsets, strict=True):
            logs = [
                _read_metrics(p)
                for s in seeds
                if (p := out / "models" / model_name(net, n, s) / "metrics.csv").is_file()
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
        unit = "L1 on valid bins (m)" if net == "depth" else "cross-entropy"
        loss_ax.set_title(f"{NET_LABELS[net]}: {unit}")
        loss_ax.set_ylabel("loss")
        loss_ax.legend(fontsize=7, ncol=2)
        std_ax.set_title(f"{NET_LABELS[net]}: std of the validation loss over a batch")
        std_ax.set_xlabel("epoch (100 training batches of 64)")
        std_ax.set_ylabel("std")
        std_ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_success_vs_runs(out: Path, subsets: tuple[int, ...], seeds: tuple[int, ...], path: Path) -> None:
    """The paper's claim at a glance: successes out of the evaluation canyons against training runs."""
    results = collect_results(out, subsets, seeds)
    fig, ax = plt.subplots(figsize=(6, 4))
    for net, colour in (("depth", "tab:blue"), ("coll", "tab:orange")):
        xs, mean, std = [], [], []
        for n in subsets:
            succ = [r["summary"]["successes"] for r in results[f"{net}_{n}"]]
            if succ:
                xs.append(n)
                mean.append(np.mean(succ))
                std.append(np.std(succ))
        if xs:
            ax.errorbar(xs, mean, yerr=std, marker="o", capsize=3, color=colour, label=NET_LABELS[net])
        paper = [(n, PAPER_TABLE1[n][net][1]) for n in subsets if n in PAPER_TABLE1]
        if paper:
            label = f"{NET_LABELS[net]}, paper"
            ax.plot(*zip(*paper, strict=True), "--", color=colour, alpha=0.6, label=label)
    ax.set_xlabel("training runs")
    ax.set_ylabel("successes (distance > 15 m)")
    ax.set_xscale("log")
    ax.set_xticks(list(subsets), [str(n) for n in subsets])
    ax.minorticks_off()  # the sizes themselves, not 4×10¹ …
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
