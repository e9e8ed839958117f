"""The default head's size, measured on `val` canyons (docs/benchmarks.md#head-size).

Each network is trained at every hidden width, Depth-Q-Net also at every epoch budget (its weight
average over the last quarter of them; Coll-Q-Net acts with its best epoch, so its budget stays), on
200 and 500 runs of the hard and of the paper family with 2 seeds, and driven in 20 `val` canyons of
its family. Every variant is compared with the reference (4096 wide, 40 epochs) paired by family,
size and seed; the cheapest variant that drives as far in every family (there, its mean paired
difference no worse than minus the reference's spread between seeds) is the one to make the default.

    python -m research.sizing run OUT       # the four sweeps, resumed when rerun
    python -m research.sizing report OUT    # OUT/report.md, OUT/sizing.json, OUT/sizing.png

OUT/<family>-<net>/ is a `depthq sweep` folder (the Coll-Q-Net sweeps read the Depth-Q-Net sweeps'
data through a symlink). The reference width is pinned, so the folders keep their names when the
default changes. Nothing here pins cores (the caller's `taskset` does).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from depthq.checkpoint import dataset_record, read_config, read_metrics
from depthq.configio import atomic_write_bytes, read_json, write_json
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import evaluation_done
from depthq.lock import exclusive
from depthq.pipeline.presets import get_preset
from depthq.pipeline.runner import run_sweep
from depthq.pipeline.sweep import Sweep, retarget, widened
from depthq.report.build import build_report
from depthq.report.cells import mean_interval
from depthq.report.tables import interval, markdown

PROG = "python -m research.sizing"
CANYONS = {"hard": "hard/val:1000-1019", "paper": "val:1000-1019"}  # the choice canyons of each family
NETS = ("depth", "coll")
WIDTHS = (512, 1024, 2048, 4096)
EPOCHS = {"depth": (20, 30, 40), "coll": ()}  # (): the trainer's default budget only
REFERENCE = (4096, 40)  # hidden width, epochs: the default before this measurement
RUNS, SIZES, SEEDS = 500, (200, 500), (0, 1)


def sweep(family: str, net: str) -> Sweep:
    """The sweep of one family and network, as `depthq sweep --preset FAMILY --runs 500 --sizes 200,500
    --seeds 0,1 --canyons CANYONS --nets NET --set hidden=… [--set epochs=…]` builds it, its reference
    width pinned."""
    grid = (("hidden", WIDTHS),) + ((("epochs", EPOCHS[net]),) if EPOCHS[net] else ())
    base = get_preset(family)
    target = retarget(base, None, CANYONS[family], None, None)
    pinned = widened(target, RUNS, name=f"{base.name} sweep", seeds=SEEDS, subsets=SIZES, nets=(net,),
                     grid=grid)
    return widened(pinned, train=(*pinned.train, ("hidden", REFERENCE[0])))


def run(out: Path, device: str = "auto") -> None:
    """Every family's Depth-Q-Net sweep, then its Coll-Q-Net sweep on the same data (a resumed sweep
    also drives again what was driven with weights its checkpoint no longer acts with)."""
    for net in NETS:
        for family in CANYONS:
            folder = out / f"{family}-{net}"
            if net != NETS[0] and not (folder / "data").exists():
                folder.mkdir(parents=True, exist_ok=True)
                (folder / "data").symlink_to((out / f"{family}-{NETS[0]}" / "data").resolve())
            run_sweep(sweep(family, net), folder, device=device, finish=build_report)


@dataclass(frozen=True)
class Point:
    """One trained model driven in its family's choice canyons."""

    family: str
    net: str
    runs: int
    seed: int
    hidden: int
    epochs: int
    distance: float  # mean m to the first collision over the canyons
    ends: int  # canyons whose end it reached
    epoch_s: float  # median seconds of a training epoch (as trained: one core, maybe beside other work)
    best_epoch: int | None = None  # the epoch of its lowest validation loss (what a Coll-Q-Net acts with)

    @property
    def variant(self) -> tuple[str, int, int]:
        return self.net, self.hidden, self.epochs

    @property
    def cell(self) -> tuple[str, int, int]:
        return self.family, self.runs, self.seed


def points(out: Path) -> list[Point]:
    """Every model of OUT's sweeps that has been driven, its settings read from its checkpoint."""
    found = []
    for summary_file in sorted(out.glob("*-*/eval/*/summary.json")):
        model = summary_file.parent.parent.parent / "models" / summary_file.parent.name
        if not (model / "config.json").is_file() or not evaluation_done(summary_file.parent):
            continue  # a reference policy's evaluation (heuristic, OU), or one to drive again
        config, summary = read_config(model), read_json(summary_file)["summary"]
        logged = read_metrics(model)
        train = config["train"]
        found.append(Point(str(dataset_record(config).family), train["model"], int(train["runs"]),
                           int(train["seed"]), int(config["head"]["hidden"]), int(train["epochs"]),
                           float(summary["distance_to_collision_mean"]), int(summary["reached_end"]),
                           float(np.nanmedian(logged["seconds"])),
                           int(logged["epoch"][np.argmin(logged["val_loss"])])))
    return found


def seed_spread(reference: list[Point]) -> float | None:
    """The reference's standard deviation between seeds, pooled over its (family, size) cells."""
    cells: dict[tuple[str, int], list[float]] = {}
    for p in reference:
        cells.setdefault((p.family, p.runs), []).append(p.distance)
    variances = [np.var(v, ddof=1) for v in cells.values() if len(v) > 1]
    return float(np.sqrt(np.mean(variances))) if variances else None


def compare(found: list[Point]) -> list[dict[str, object]]:
    """Per variant: its distance per family and size (mean over seeds); per family its paired
    difference from the reference of its network (mean and 95 % interval over the cells both hold)
    and the reference's spread between seeds there; whether it drives as far in every family; and its
    cost (width × epochs, and the measured seconds per epoch). Per family, not pooled: the paper
    family's canyons are nearly all driven to the end by every variant, and pooled they would halve
    a loss in the hard family."""
    by_variant: dict[tuple[str, int, int], dict[tuple[str, int, int], Point]] = {}
    for p in found:
        by_variant.setdefault(p.variant, {})[p.cell] = p
    rows = []
    for (net, hidden, epochs), cells in sorted(by_variant.items(), key=lambda kv: _cost(*kv[0])):
        reference = by_variant.get((net, *REFERENCE), {})
        families = {}
        for family in CANYONS:
            shared = sorted(c for c in set(cells) & set(reference) if c[0] == family)
            diffs = [cells[c].distance - reference[c].distance for c in shared]
            spread = seed_spread([p for c, p in reference.items() if c[0] == family])
            complete = len(shared) == len(SIZES) * len(SEEDS)
            families[family] = {
                "difference": float(np.mean(diffs)) if diffs else None, "interval": interval(diffs),
                "pairs": len(shared), "spread": spread,
                "as_far": None if not complete or spread is None else bool(np.mean(diffs) >= -spread),
            }
        verdicts = [f["as_far"] for f in families.values()]
        rows.append({
            "net": net, "hidden": hidden, "epochs": epochs,
            "distance": {f"{f}/{n}": [cells[c].distance for c in sorted(cells) if c[:2] == (f, n)]
                         for f in CANYONS for n in SIZES},
            "families": families, "pairs": sum(f["pairs"] for f in families.values()),
            "as_far": None if None in verdicts else all(verdicts),
            "epoch_s": float(np.median([p.epoch_s for p in cells.values()])),
            "best_epochs": sorted(p.best_epoch for p in cells.values() if p.best_epoch is not None),
        })
    return rows


def _cost(net: str, hidden: int, epochs: int) -> tuple[str, int, int]:
    """The order of variants: by network, then the training's work (width × epochs), then width."""
    return net, hidden * epochs, hidden


def choice(rows: list[dict[str, object]], net: str) -> dict[str, object] | None:
    """The cheapest variant of `net` that drives as far as its reference; None until all are measured."""
    mine = [r for r in rows if r["net"] == net]
    if not mine or any(r["as_far"] is None for r in mine):
        return None
    return min((r for r in mine if r["as_far"]), key=lambda r: _cost(net, int(r["hidden"]), int(r["epochs"])))


def same_net_budget(row: dict[str, object], budgets: tuple[int, ...] = EPOCHS["depth"]) -> int | None:
    """The fewest epochs that train every model of a Coll-Q-Net variant into the same net it acts with
    now: it acts with its best epoch, and nothing in its training depends on the budget (no schedule,
    one random stream), so a budget of E epochs gives the same weights wherever its best epoch ≤ E.
    None while a model's best epoch is unknown."""
    best = row["best_epochs"]
    if not best or len(best) < row["pairs"]:
        return None
    return min(e for e in (*budgets, int(row["epochs"])) if e >= max(best))


def _difference(mean: float | None, ci: tuple[float, float] | None) -> str:
    if mean is None:
        return "–"
    return f"{mean:+.2f}" + ("" if ci is None else f" [{ci[0]:+.2f}, {ci[1]:+.2f}]")


def figure(found: list[Point], path: Path) -> None:
    """m to the first collision against the hidden width, a panel per family and size: each epoch
    budget's mean over seeds (the bars span the seeds), Coll-Q-Net dashed."""
    fig, axes = plt.subplots(len(CANYONS), len(SIZES), figsize=(5 * len(SIZES), 3.6 * len(CANYONS)),
                             sharex=True, squeeze=False)
    names = {"depth": "Depth-Q-Net", "coll": "Coll-Q-Net"}
    for (family, runs), ax in zip([(f, n) for f in CANYONS for n in SIZES], axes.flat, strict=True):
        for net, epochs in sorted({(p.net, p.epochs) for p in found}):
            mine = [p for p in found if (p.net, p.epochs, p.family, p.runs) == (net, epochs, family, runs)]
            widths = sorted({p.hidden for p in mine})
            if not widths:
                continue
            values = [[p.distance for p in mine if p.hidden == w] for w in widths]
            mean = np.array([np.mean(v) for v in values])
            spread = [mean - [min(v) for v in values], [max(v) for v in values] - mean]
            ax.errorbar(widths, mean, yerr=spread, capsize=3, ls="-" if net == "depth" else "--",
                        marker="o" if net == "depth" else "s", label=f"{names[net]}, {epochs} epochs")
        ax.set_xscale("log", base=2)
        ax.set_xticks(WIDTHS, [str(w) for w in WIDTHS])
        ax.set_title(f"{family} val canyons, {runs} runs")
        ax.set_ylabel("m to the first collision")
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("hidden width")
    legend = {label: handle for ax in axes.flat for handle, label in zip(*ax.get_legend_handles_labels(),
                                                                         strict=True)}
    if legend:
        fig.legend(legend.values(), legend.keys(), loc="lower center", ncol=len(legend), fontsize=8)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def report(out: Path) -> str:
    """OUT/report.md (and the same as OUT/sizing.json): one row per variant, and each network's choice."""
    found = points(out)
    rows = compare(found)
    head = ["network", "hidden", "epochs", *(f"{f} val, {n} runs: m" for f in CANYONS for n in SIZES),
            *(f"{f}: paired difference from 4096/40, m" for f in CANYONS), "pairs", "as far",
            "s/epoch as trained (shared core?)"]
    body = [[r["net"], r["hidden"], r["epochs"],
             *(mean_interval(v, ".2f") for v in r["distance"].values()),
             *(_difference(f["difference"], f["interval"]) for f in r["families"].values()),
             r["pairs"], {None: "not yet", True: "yes", False: "no"}[r["as_far"]], f"{r['epoch_s']:.2f}"]
            for r in rows]
    table = markdown([dict(zip(head, map(str, cells), strict=True)) for cells in body])
    lines = ["# The default head's size, on val canyons", "", table, "", "![m to the first collision against "
             "the hidden width](sizing.png)", ""]
    for net in NETS:
        chosen = choice(rows, net)
        families = next((r["families"] for r in rows
                         if r["net"] == net and (r["hidden"], r["epochs"]) == REFERENCE), {})
        spreads = ", ".join(f"{f} {s['spread']:.2f} m" for f, s in families.items()
                            if s["spread"] is not None) or "not yet measured"
        chosen_text = ("not yet measured" if chosen is None
                       else f"{chosen['hidden']} wide, {chosen['epochs']} epochs")
        lines.append(f"- {net}: the reference's spread between seeds: {spreads}; "
                     f"the cheapest that drives as far in every family: {chosen_text}")
        if net == "coll" and chosen is not None:
            lines.append(f"  - its best epochs {chosen['best_epochs']}: the same nets in "
                         f"{same_net_budget(chosen)} epochs (a Coll-Q-Net acts with its best epoch)")
    text = "\n".join(lines) + "\n"
    atomic_write_bytes(out / "report.md", text.encode())
    write_json(out / "sizing.json", {"rows": rows, "choices": {n: choice(rows, n) for n in NETS},
                                     "points": [asdict(p) for p in found]})
    figure(found, out / "sizing.png")
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    go = actions.add_parser("run", help="the four sweeps (resumed)")
    go.add_argument("out", type=Path, help="the experiment's folder (created; resumed)")
    go.add_argument("--device", default="auto", help="torch device (default: auto)")
    rep = actions.add_parser("report", help="OUT/report.md and OUT/sizing.json from what OUT holds")
    rep.add_argument("out", type=Path, help="the experiment's folder")
    args = parser.parse_args(argv)

    def work() -> int:
        if args.action == "report" and not args.out.is_dir():
            raise ConfigError(f"{args.out}: no such experiment folder")
        with exclusive(args.out, "OUT"):  # one writer per experiment folder
            if args.action == "run":
                run(args.out, args.device)
            print(report(args.out))
        return 0

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
