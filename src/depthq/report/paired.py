"""The paired comparison behind the README's headline: Depth-Q-Net against Coll-Q-Net trained on the
same runs with the same seed, per size of a sweep folder, each network's mean [95 % interval] and the
per-seed difference's; with `--claim ID`, written as that claim's evidence in docs/findings.json.

    python -m depthq.report.paired SWEEP [--sizes 200,500] [--seeds 0,1,2] [--claim table-i]

SWEEP is any `depthq sweep` / `depthq reproduce` folder of both networks (e.g. a preset's Table I in
the `eval` canyons), or a folder of evaluations named by `--pattern`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, NamedTuple

from depthq.configio import read_json
from depthq.errors import ConfigError, guarded
from depthq.networks import CollQNet, DepthQNet
from depthq.pipeline.layout import model_name
from depthq.pipeline.sweep import Settings, Variant, differing, parse_ints, parse_setting
from depthq.report.cells import evaluation_summary, mean_interval
from depthq.report.findings import FINDINGS, Evidence, record_evidence

PROG = "python -m depthq.report.paired"
PATTERN = "eval/{model}"  # a sweep's evaluation of a model (its folder name: {net}_n{n}_s{seed}…)
PAIRED = (("to first collision (m)", "distance_to_collision_mean", ".2f"), ("successes", "successes", ".1f"),
          ("closest mean (m)", "closest_mean", ".2f"))
PAIR = (CollQNet.name, DepthQNet.name)  # the paper's comparison: its baseline, then its network
Summaries = dict[int, dict[str, Any]]  # seed → an evaluation's summary
Results = dict[int, tuple[Summaries, Summaries]]  # size → (Coll-Q-Net's, Depth-Q-Net's) summaries


class Pairs(NamedTuple):
    """Two evaluations' values of one measure over the seeds both have, and the per-seed difference."""

    seeds: list[int]  # in order
    first: list[float]
    second: list[float]
    diff: list[float]  # second − first, seed by seed


def by_seed(first: Summaries, second: Summaries, key: str = "distance_to_collision_mean") -> Pairs:
    """`key` of the summaries of `first` and `second` paired by seed (networks trained on the same runs
    with the same seed make their comparison a paired one): over the seeds both have."""
    seeds = sorted(set(first) & set(second))
    a, b = ([float(summaries[s][key]) for s in seeds] for summaries in (first, second))
    return Pairs(seeds, a, b, [y - x for x, y in zip(a, b, strict=True)])


def paired_results(sweep: Path, sizes: tuple[int, ...], seeds: tuple[int, ...], pattern: str = PATTERN,
                   variant: Variant = ()) -> Results:
    """Per size with a seed of both networks evaluated: (Coll-Q-Net's, Depth-Q-Net's) summaries of
    the seeds both have, each read once. `pattern` names a model's evaluation folder under `sweep`;
    `variant`: the sweep's models in it (`depthq sweep --set`'s, one value each)."""
    results: Results = {}
    differs = {net: differing(net, variant, _sweep_train(sweep)) for net in PAIR}
    for n in sizes:
        for seed in seeds:
            coll, depth = (evaluation_summary(Path(sweep) / pattern.format(
                net=net, n=n, seed=seed, model=model_name(net, n, seed, differs[net])))
                for net in PAIR)
            if coll and depth:
                both = results.setdefault(n, ({}, {}))
                both[0][seed], both[1][seed] = coll, depth
    return results


def _sweep_train(sweep: Path) -> Settings:
    """The training settings every model of a sweep folder has (its setup's, as `Sweep.train`); none
    for a folder of evaluations alone (no reproduce.json, e.g. models driven in fresh canyons)."""
    marker = Path(sweep) / "reproduce.json"
    if not Path(sweep).is_dir():
        raise ConfigError(f"{sweep}: no such folder")
    if not marker.is_file():
        return ()
    setup = read_json(marker)["sweep"]
    keys = ("epochs", "train_batches", "val_batches")
    return tuple((k, setup[k]) for k in keys if setup.get(k) is not None)


def paired(results: Results) -> str:
    """Markdown: Depth-Q-Net against Coll-Q-Net trained on the same data with the same seed, per size
    of a sweep folder (`paired_results`): each network's mean [95 % interval] and the per-seed
    difference's (seeds trained on the same runs make the comparison a paired one); sizes or seeds
    not evaluated are left out of their row."""
    lines = ["| runs | seeds | measure | Coll-Q-Net | Depth-Q-Net | Depth − Coll, paired by seed |",
             "|---|---|---|---|---|---|"]
    for n, (coll, depth) in results.items():
        for label, key, fmt in PAIRED:
            pairs = by_seed(coll, depth, key)
            cells = [mean_interval(v, fmt) for v in (pairs.first, pairs.second, pairs.diff)]
            lines.append(f"| {n} | {','.join(map(str, coll))} | {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def paired_evidence(sweep: Path, results: Results) -> dict[str, str]:
    """The paired comparison of a sweep folder's `results` (`paired_results`) in words, one sentence
    per size, keyed by where it was measured ('hard/eval, 4 Hz, 500 runs'): the report's evidence for
    a claim (docs/findings.json)."""
    marker = Path(sweep) / "reproduce.json"
    if not marker.is_file():
        raise ConfigError(f"{sweep}: not a sweep folder (no reproduce.json), so it names no canyons to claim")
    record = read_json(marker)["sweep"]
    out = {}
    for n, summaries in results.items():
        _, coll, depth, diff = by_seed(*summaries)
        ahead = sum(d > 0 for d in diff)
        key = f"{record['canyons']}, {record['decision_hz']:g} Hz, {n} runs"
        out[key] = (f"to the first collision Depth-Q-Net {mean_interval(depth, '.2f')} m, Coll-Q-Net "
                    f"{mean_interval(coll, '.2f')} m; Depth-Q-Net ahead in {ahead} of {len(diff)} seeds "
                    f"(paired difference {mean_interval(diff, '.2f')} m)")
    return out


def _one(key: str, values: tuple[Any, ...]) -> Any:
    if len(values) != 1:
        raise ConfigError(f"--set {key}: one value here, got {len(values)}")
    return values[0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    parser.add_argument("sweep", type=Path, help="a sweep folder of both networks (or of their evaluations)")
    parser.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1,2")
    parser.add_argument("--sizes", default="500", help="training runs, e.g. 200,500")
    parser.add_argument("--pattern", default=PATTERN,
                        help="a model's evaluation folder under SWEEP, from {model} (the sweep's folder "
                             "name), {net}, {n} and {seed}")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="the sweep's models of this variant, as `depthq sweep --set` gave it "
                             "(one value each; repeatable)")
    parser.add_argument("--claim", help="write the comparison as evidence of this claim of the findings "
                                        "file (e.g. table-i), one entry per size")
    parser.add_argument("--findings", type=Path, default=FINDINGS, help="--claim: the findings file")
    args = parser.parse_args(argv)
    return guarded(PROG, lambda: _act(args, argv))


def _act(args: argparse.Namespace, argv: list[str] | None) -> int:
    sizes, seeds = parse_ints(args.sizes, "--sizes"), parse_ints(args.seeds, "--seeds")
    variant = tuple((key, _one(key, values)) for key, values in map(parse_setting, args.set))
    results = paired_results(args.sweep, sizes, seeds, args.pattern, variant)  # the summaries read once
    print(paired(results))
    if args.claim:
        command = f"{PROG} " + " ".join(argv or sys.argv[1:])
        for key, text in paired_evidence(args.sweep, results).items():
            record_evidence(args.claim, key, Evidence(text, command), args.findings)
            print(f"{args.findings}: claim {args.claim}, {key}: {text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
