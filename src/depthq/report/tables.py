"""Table I and Table II from the files a reproduction wrote (never from hand-written numbers)."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import t as student_t

from depthq.configio import read_json
from depthq.data.stats import PAPER_TABLE2
from depthq.networks import Network, get_network, network_names
from depthq.pipeline.sweep import Model, Sweep, Variant, variant_label
from depthq.sim.canyon import FAMILIES, split_family


def paper_networks() -> list[Network]:
    """The networks with the paper's Table I (`Network.paper`, mean over its 3 seeds, for comparison
    only), in the order registered."""
    return [get_network(name) for name in network_names() if get_network(name).paper]


def interval(values: list[float]) -> tuple[float, float] | None:
    """The 95 % Student-t interval of the mean over seeds (None for one seed)."""
    if len(values) < 2:
        return None

    half = student_t.ppf(0.975, len(values) - 1) * np.std(values, ddof=1) / np.sqrt(len(values))
    return float(np.mean(values) - half), float(np.mean(values) + half)


def _cell(values: list[float], fmt: str, with_interval: bool = False) -> str:
    """'mean (std)' over seeds, std with n − 1; `with_interval`: then '[low, high]' (95 %)."""
    if not values:
        return "–"
    std = f"{np.std(values, ddof=1):{fmt}}" if len(values) > 1 else "–"
    text = f"{np.mean(values):{fmt}} ({std})"
    if with_interval and (ci := interval(values)) is not None:
        text += f" [{ci[0]:{fmt}}, {ci[1]:{fmt}}]"
    return text


def collect_results(out: Path, sweep: Sweep) -> dict[Model, dict[str, Any]]:
    """The evaluation summaries of the sweep's models that exist."""
    results = {}
    for model in sweep.models():
        path = out / "eval" / model.name / "summary.json"
        if path.is_file():
            results[model] = read_json(path)
    return results


def per_seed(
    results: dict[Model, dict[str, Any]], net: str, n: int, variant: Variant
) -> list[dict[str, Any]]:
    """The summaries of one (network, size, variant), in seed order."""
    return [
        r for m, r in sorted(results.items(), key=lambda item: item[0].seed)
        if (m.net, m.runs, m.variant) == (net, n, variant)
    ]


def _circling(runs: list[dict[str, Any]]) -> float:
    """Share of runs that reached the time limit within 2 m of the spawn: the policy turned on the spot."""
    return float(np.mean([r["end_reason"] == "time_limit" and r["distance"] < 2.0 for r in runs]))


def _groups(sweep: Sweep) -> list[tuple[Variant, int, dict[str, str]]]:
    """(variant, size, the row's first cells): one table row each. A sweep with settings (`--set`)
    names them in every row, even a single one: the table must say what it measured."""
    named = bool(sweep.grid)
    return [
        (variant, n, ({"variant": variant_label(variant)} if named else {}) | {"runs": str(n)})
        for variant in sweep.variants()
        for n in sweep.subsets
    ]


def table1_rows(out: Path, sweep: Sweep) -> list[dict[str, str]]:
    """The paper's Table I columns, mean (std) over seeds and the 95 % interval of the mean for
    distance and success; one row per (variant, training-set size)."""
    results = collect_results(out, sweep)
    published = sorted(paper_networks(), key=lambda network: network.name)  # as the columns: by name
    heading = " / ".join(network.label for network in published)
    rows = []
    for variant, n, row in _groups(sweep):
        for net in sorted(sweep.nets):
            runs = per_seed(results, net, n, variant)
            network = get_network(net)
            label = network.label
            row[f"distance {label}"] = _cell([r["summary"]["distance_mean"] for r in runs], ".2f", True)
            row[f"success {label}"] = _cell([r["summary"]["successes"] for r in runs], ".1f", True)
            row[f"imitation {label}"] = _cell([r["summary"]["imitation_loss_mean"] for r in runs], ".3f")
            row[f"circling {label}"] = _cell([_circling(r["runs"]) for r in runs], ".0%")
            if reaches_end_goal(sweep):  # the hard family: metrics that do not saturate
                row[f"to collision {label}"] = _cell(
                    [r["summary"]["distance_to_collision_mean"] for r in runs], ".2f"
                )
                row[f"closest {label}"] = _cell([r["summary"]["closest_mean"] for r in runs], ".2f")
            row[f"seeds {label}"] = str(len(runs))
            offline = f"{network.metric_title} {label}"
            row[offline] = _cell([r["offline"]["value"] for r in runs if "offline" in r], ".3f")
        cells = [str(network.paper[n][1]) for network in published if n in network.paper]
        row[f"paper: success {heading}"] = " / ".join(cells) if cells else "–"
        rows.append(row)
    return rows


def per_seed_rows(out: Path, sweep: Sweep) -> list[dict[str, str]]:
    """Successes / mean distance of every seed: the spread that a mean (std) over 3 seeds hides; and a
    net with depth bins' dead outputs per seed (`depthq.train.dead_outputs`, from the offline metric)."""
    results = collect_results(out, sweep)
    rows = []
    for variant, n, row in _groups(sweep):
        for net in sweep.nets:
            evaluations = per_seed(results, net, n, variant)
            cells = [f"{r['summary']['successes']}/{r['summary']['distance_mean']:.1f}" for r in evaluations]
            row[f"{get_network(net).label}: successes/m per seed"] = ", ".join(cells) or "–"
            if get_network(net).outputs_bins:
                row[f"{get_network(net).label}: dead outputs per seed"] = _dead_cell(evaluations)
        published = paper_networks()
        cells = [f"{net.paper[n][1]}/{net.paper[n][0]}" for net in published if n in net.paper]
        row[f"paper {', '.join(network.label for network in published)} (mean)"] = ", ".join(cells or ["–"])
        rows.append(row)
    return rows


def _dead_cell(evaluations: list[dict[str, Any]]) -> str:
    """'dead/outputs' of each seed's evaluation ('?' where its offline metric was not measured)."""
    cells = [f"{len(o['dead_outputs'])}/{o['outputs']}" if "dead_outputs" in (o := r.get("offline") or {})
             else "?" for r in evaluations]
    return ", ".join(cells) or "–"


def reference_rows(out: Path, reaches_end: bool = False) -> list[dict[str, str]]:
    """The heuristic expert and OU exploration: mean (std) over canyons (`reaches_end`: with the hard
    family's distance to the first collision and closest approach)."""
    rows = []
    for ref in ("heuristic", "ou"):
        path = out / "eval" / ref / "summary.json"
        if path.is_file():
            s = read_json(path)["summary"]
            row = {
                "policy": ref,
                "distance": f"{s['distance_mean']:.2f} ({s['distance_std']:.2f})",
                "success": f"{s['successes']}/{s['runs']}",
                "imitation": f"{s['imitation_loss_mean']:.3f} ({s['imitation_loss_std']:.3f})",
            }
            if reaches_end:
                row["to collision"] = (
                    f"{s['distance_to_collision_mean']:.2f} ({s['distance_to_collision_std']:.2f})"
                )
                row["closest mean / min"] = f"{s['closest_mean']:.2f} / {s['closest_min']:.2f}"
            rows.append(row)
    return rows


def reaches_end_goal(sweep: Sweep) -> bool:
    """Whether the sweep's evaluation canyons are judged by reaching their end (the hard family)."""
    return FAMILIES[split_family(sweep.canyons)[0]].goal == "end"


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
