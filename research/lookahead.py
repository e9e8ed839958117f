"""The lookahead table (docs/ablation.md#lookahead-eval): the one-step and the lookahead Depth-Q-Net
against Coll-Q-Net in the hard family's 20 `eval` canyons, 3 seeds, with 95 % intervals.

    depthq sweep --preset hard --out runs/hard-eval                       # Table I: K = 1 and Coll-Q-Net
    depthq sweep --preset hard --nets depth --sizes 200,500 --seeds 0,1,2 \\
        --set lookahead=3 --out runs/hard-eval-look                       # the lookahead Depth-Q-Net
    python -m research.lookahead runs/hard-eval runs/hard-eval-look   # this table, as markdown

K = 3 and its selection rule (the discounted mean) were chosen on `hard/val` canyons
(docs/ablation.md#lookahead); the `eval` canyons only measure the choice. The last rows pair the
two Depth-Q-Nets by seed (same data, same canyons): the interval of their difference.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/ablation.md#lookahead-eval came from the code of commit 8671b70 (2026-11-23: the last change of
that page's tables).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from depthq.report.cells import evaluation_summary, mean_interval

SIZES, SEEDS, K = (200, 500), (0, 1, 2), 3
NETS = (  # label, folder argument index, model name pattern
    ("Coll-Q-Net", 0, "coll_n{n}_s{s}"),
    ("Depth-Q-Net, one step", 0, "depth_n{n}_s{s}"),
    (f"Depth-Q-Net, lookahead {K}", 1, f"depth_n{{n}}_s{{s}}_lookahead{K}"),
)
METRICS = (
    ("successes", "successes / 20", ".1f"),
    ("distance_to_collision_mean", "to first collision (m)", ".2f"),
    ("closest_mean", "closest (m)", ".2f"),
)


def table(folders: tuple[Path, Path], sizes: tuple[int, ...] = SIZES, seeds: tuple[int, ...] = SEEDS) -> str:
    """Markdown: each network and size over `seeds` (the sweep folders of K = 1 and of the lookahead),
    then the lookahead's difference from the one-step net, paired by seed."""
    lines = ["| network | runs | " + " | ".join(title for _, title, _ in METRICS) + " | per seed (m) |",
             "|---|---|" + "---|" * (len(METRICS) + 1)]
    per = {}
    for n in sizes:
        for label, which, pattern in NETS:
            evals = folders[which] / "eval"
            found = {s: m for s in seeds if (m := evaluation_summary(evals / pattern.format(n=n, s=s)))}
            per[label, n] = found
            cells = [mean_interval([m[key] for m in found.values()], fmt, len(seeds))
                     for key, _, fmt in METRICS]
            distances = ", ".join(f"{m['distance_to_collision_mean']:.2f}" for m in found.values())
            lines.append(f"| {label} | {n} | " + " | ".join(cells) + f" | {distances} |")
    for n in sizes:
        one, look = per[NETS[1][0], n], per[NETS[2][0], n]
        both = [s for s in seeds if s in one and s in look]
        diffs = {key: [look[s][key] - one[s][key] for s in both] for key, _, _ in METRICS}
        cells = [mean_interval(diffs[key], fmt, len(seeds)) for key, _, fmt in METRICS]
        lines.append(f"| lookahead {K} − one step, paired by seed | {n} | " + " | ".join(cells) + " | |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.lookahead",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("one_step", type=Path,
                        help="the sweep folder of Coll-Q-Net and the one-step Depth-Q-Net")
    parser.add_argument("lookahead", type=Path, help=f"the sweep folder of the lookahead-{K} Depth-Q-Net")
    args = parser.parse_args(argv)
    print(table((args.one_step, args.lookahead)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
