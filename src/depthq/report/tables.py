"""Table I and Table II from the files a reproduction wrote (never from hand-written numbers)."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from depthq.configio import read_json
from depthq.report.layout import NETS, model_name

NET_LABELS = {"coll": "CQN", "depth": "DQN"}
# The paper's Table I (mean over its 3 seeds), for comparison only: runs → net → (distance m, successes /20).
PAPER_TABLE1: dict[int, dict[str, tuple[float, float]]] = {
    50: {"coll": (1.07, 0.0), "depth": (1.68, 0.0)},
    100: {"coll": (1.04, 0.0), "depth": (4.91, 0.7)},
    200: {"coll": (2.69, 0.0), "depth": (12.19, 8.0)},
    500: {"coll": (6.72, 2.7), "depth": (21.96, 20.0)},
    700: {"coll": (8.32, 4.7), "depth": (22.21, 20.0)},
    900: {"coll": (14.14, 11.3), "depth": (22.30, 20.0)},
}


def _mean_std(values: list[float], fmt: str) -> str:
    if not values:
        return "–"
    return f"{np.mean(values):{fmt}} ({np.std(values):{fmt}})"


def collect_results(out: Path, subsets: tuple[int, ...], seeds: tuple[int, ...]) -> dict[str, Any]:
    """Per (net, n): the per-seed summaries of the evaluations that exist."""
    results: dict[str, Any] = {}
    for n in subsets:
        for net in NETS:
            per_seed = []
            for seed in seeds:
                path = out / "eval" / model_name(net, n, seed) / "summary.json"
                if path.is_file():
                    per_seed.append(read_json(path))
            results[f"{net}_{n}"] = per_seed
    return results


def _circling(runs: list[dict[str, Any]]) -> float:
    """Share of runs that reached the time limit within 2 m of the spawn: the policy turned on the spot."""
    return float(np.mean([r["end_reason"] == "time_limit" and r["distance"] < 2.0 for r in runs]))


def table1_rows(out: Path, subsets: tuple[int, ...], seeds: tuple[int, ...]) -> list[dict[str, str]]:
    """The paper's Table I columns, mean (std) over seeds, one row per training-set size."""
    results = collect_results(out, subsets, seeds)
    rows = []
    for n in subsets:
        row = {"runs": str(n)}
        for net in ("coll", "depth"):
            runs = results[f"{net}_{n}"]
            label = NET_LABELS[net]
            row[f"distance {label}"] = _mean_std([r["summary"]["distance_mean"] for r in runs], ".2f")
            row[f"success {label}"] = _mean_std([r["summary"]["successes"] for r in runs], ".1f")
            row[f"imitation {label}"] = _mean_std([r["summary"]["imitation_loss_mean"] for r in runs], ".3f")
            row[f"circling {label}"] = _mean_std([_circling(r["runs"]) for r in runs], ".0%")
            row[f"seeds {label}"] = str(len(runs))
        coll, depth = results[f"coll_{n}"], results[f"depth_{n}"]
        row["cross-entropy CQN"] = _mean_std([r["offline"]["value"] for r in coll if "offline" in r], ".3f")
        row["abs diff DQN"] = _mean_std([r["offline"]["value"] for r in depth if "offline" in r], ".3f")
        paper = PAPER_TABLE1.get(n)
        row["paper: success CQN / DQN"] = f"{paper['coll'][1]} / {paper['depth'][1]}" if paper else "–"
        rows.append(row)
    return rows


def per_seed_rows(out: Path, subsets: tuple[int, ...], seeds: tuple[int, ...]) -> list[dict[str, str]]:
    """Successes / mean distance of every seed: the spread that a mean (std) over 3 seeds hides."""
    results = collect_results(out, subsets, seeds)
    rows = []
    for n in subsets:
        row = {"runs": str(n)}
        for net in ("depth", "coll"):
            summaries = [r["summary"] for r in results[f"{net}_{n}"]]
            cells = [f"{s['successes']}/{s['distance_mean']:.1f}" for s in summaries]
            row[f"{NET_LABELS[net]}: successes/m per seed"] = ", ".join(cells) or "–"
        paper = PAPER_TABLE1.get(n)
        cells = [f"{paper[net][1]}/{paper[net][0]}" for net in ("depth", "coll")] if paper else ["–"]
        row["paper DQN, CQN (mean)"] = ", ".join(cells)
        rows.append(row)
    return rows


def reference_rows(out: Path) -> list[dict[str, str]]:
    """The heuristic expert and OU exploration: mean (std) over canyons."""
    rows = []
    for ref in ("heuristic", "ou"):
        path = out / "eval" / ref / "summary.json"
        if path.is_file():
            s = read_json(path)["summary"]
            rows.append(
                {
                    "policy": ref,
                    "distance": f"{s['distance_mean']:.2f} ({s['distance_std']:.2f})",
                    "success": f"{s['successes']}/{s['runs']}",
                    "imitation": f"{s['imitation_loss_mean']:.3f} ({s['imitation_loss_std']:.3f})",
                }
            )
    return rows


def markdown(rows: list[dict[str, str]]) -> str:
    if not rows:
        return "(no rows)\n"
    head = list(rows[0])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r[h] for h in head) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def csv_text(rows: list[dict[str, str]]) -> str:
    text = io.StringIO()
    if rows:
        writer = csv.DictWriter(text, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return text.getvalue()


def table2_rows(stats: dict[str, Any], subsets: tuple[int, ...]) -> list[dict[str, str]]:
    """Table II: runs, samples and samples without collision frames per subset, next to the paper's."""
    from depthq.data.stats import PAPER_TABLE2

    wanted = {str(n) for n in subsets} | {"val"}
    rows = []
    for row in stats["table"]:
        if row["subset"] not in wanted:
            continue
        paper = PAPER_TABLE2.get(int(row["subset"])) if row["subset"].isdigit() else None
        rows.append(
            {
                "runs": row["subset"],
                "samples (CQN)": str(row["samples"]),
                "samples without collision (DQN)": str(row["samples_without_collision"]),
                "paper: samples / without collision": f"{paper[0]} / {paper[1]}" if paper else "–",
                "ours / paper": f"{row['samples'] / paper[0]:.2f}" if paper else "–",
                "mean run length": f"{row['mean_run_length']:.1f}",
                "ended in a bump": f"{row['collision_fraction']:.0%}",
            }
        )
    return rows
