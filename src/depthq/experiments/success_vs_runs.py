"""Draw docs/success_vs_runs.png, the README's figure, from the current per-seed table of docs/results.md.

    python -m depthq.experiments.success_vs_runs     # rewrites docs/success_vs_runs.png

The numbers come from the first "Per seed" table of docs/results.md (successes / mean distance per
seed, and the paper's means), which `depthq reproduce --preset paper` produced; nothing is typed in
here, so the figure follows the page.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

Row = tuple[int, list[int], list[int], float, float]


def per_seed_table(text: str) -> list[Row]:
    """(runs, DQN successes per seed, CQN successes per seed, paper DQN mean, paper CQN mean) rows."""
    block = text.split("Per seed (successes / mean distance in m):", 1)[1]
    rows = []
    for line in block.splitlines()[1:]:
        if not line.startswith("|"):
            if rows:
                break
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        if not cells[0].isdigit():
            continue
        dqn = [int(x.split("/")[0]) for x in cells[1].split(",")]
        cqn = [int(x.split("/")[0]) for x in cells[2].split(",")]
        paper = re.findall(r"([\d.]+)/[\d.]+", cells[3])
        rows.append((int(cells[0]), dqn, cqn, float(paper[0]), float(paper[1])))
    return rows


def draw(rows: list[Row], path: Path) -> None:
    """Successes against training runs: each seed a dot, the seeds' mean and the paper's as lines."""
    runs = [r[0] for r in rows]
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    for k, (label, colour, paper_label) in enumerate(
        [("Depth-Q-Net", "tab:blue", "paper Depth-Q-Net"), ("Coll-Q-Net", "tab:orange", "paper Coll-Q-Net")]
    ):
        seeds = [r[1 + k] for r in rows]
        mean = [sum(s) / len(s) for s in seeds]
        for i, s in enumerate(seeds):
            ax.scatter([runs[i]] * len(s), s, color=colour, alpha=0.35, s=14, linewidths=0)
        ax.plot(runs, mean, "-o", color=colour, label=f"{label} (depthq, mean of {len(seeds[0])} seeds)")
        ax.plot(runs, [r[3 + k] for r in rows], "--", color=colour, alpha=0.7, label=paper_label)
    ax.set_xscale("log")
    ax.set_xticks(runs, [str(n) for n in runs])
    ax.minorticks_off()
    ax.set_ylim(-0.5, 20.5)
    ax.set_yticks(range(0, 21, 5))
    ax.set_xlabel("training runs (OU exploration)")
    ax.set_ylabel("successes of 20 eval canyons")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m depthq.experiments.success_vs_runs",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--docs", type=Path, default=Path("docs"),
                        help="the folder holding results.md, where success_vs_runs.png is written "
                             "(default: docs, run from the repository root)")
    args = parser.parse_args(argv)
    rows = per_seed_table((args.docs / "results.md").read_text(encoding="utf-8"))
    draw(rows, args.docs / "success_vs_runs.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
