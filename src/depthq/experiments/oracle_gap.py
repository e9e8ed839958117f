"""The oracle gap (docs/oracle_gap.md): Depth-Q-Net candidates, one factor at a time, against
Coll-Q-Net, in the hard family's `val` canyons; and each model's agreement with the one-step oracle
along its own runs.

    python -m depthq.experiments.oracle_gap run OUT [--seeds 0,1] [--sizes 500]
    python -m depthq.experiments.oracle_gap table OUT [--seeds 0,1] [--sizes 500]
    python -m depthq.experiments.oracle_gap paired SWEEP [--seeds 0,1,2] [--sizes 200,500]

`run` runs (or resumes) one `depthq sweep` per candidate into OUT, all sharing OUT's dataset, then
measures the agreement of every finished evaluation (OUT/agreement.json, kept: an evaluation is
measured once); `table` prints the Markdown table of what has finished. The `eval` canyons are never
driven here. `paired` reads any sweep folder of both networks (e.g. a preset's Table I in the `eval`
canyons) and compares them seed by seed.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from depthq.cli import main as depthq
from depthq.configio import read_json, write_json
from depthq.evaluate.oracle import Oracle
from depthq.experiments.cells import mean_interval
from depthq.experiments.cli import guarded
from depthq.report.findings import FINDINGS, Evidence, record_evidence
from depthq.report.presets import get_preset
from depthq.report.probe import measure_agreement
from depthq.report.sweep import Sweep, parse_ints, parse_setting, retarget, widened


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
    return Candidate(name, ("head_form=concat", *sets))


CANDIDATES = (
    Candidate("Coll-Q-Net, for scale", net="coll"),
    paper_head("Depth-Q-Net, the paper's head"),
    paper_head("keep the samples before each run's end (horizon 1)", "samples.horizon=1"),
    paper_head("head width 1024", "hidden=1024"),
    Candidate("per-action head (scene and action apart)", ("head_form=per_action",)),
    paper_head("4 × 4 grid feature, head width 1024", "trunk=efficientnet_lite0_grid", "hidden=1024"),
    paper_head("relative depth loss", "depth_loss=relative"),
    paper_head("bootstrapped value, γ = 0.5", "bootstrap=0.5"),
    paper_head("bootstrapped value, γ = 0.9", "bootstrap=0.9"),
    paper_head("bootstrapped value, γ = 0.95", "bootstrap=0.95"),
    paper_head("bootstrapped value, γ = 0.98", "bootstrap=0.98"),
    paper_head("bootstrapped value γ = 0.9, relative loss", "bootstrap=0.9", "depth_loss=relative"),
    paper_head("mirrored samples", "mirror=true"),
    paper_head("mirrored samples, bootstrapped value γ = 0.9", "mirror=true", "bootstrap=0.9"),
    Candidate("Coll-Q-Net, mirrored samples", ("mirror=true",), net="coll"),
    Candidate("depth-first head (perception, then dynamics; the default)"),
)


@dataclass(frozen=True)
class Setup:
    """Where the candidates run: a preset's dataset, its `val` canyons, the sizes and seeds."""

    preset: str = "hard"
    canyons: str | None = "hard/val:1000-1019"  # None: the preset's own
    runs: int = 500
    sizes: tuple[int, ...] = (500,)
    seeds: tuple[int, ...] = (0,)


def sweep_args(setup: Setup, candidate: Candidate, seed: int, out: Path) -> list[str]:
    args = ["sweep", "--preset", setup.preset, "--runs", str(setup.runs),
            "--sizes", ",".join(map(str, setup.sizes)), "--seeds", str(seed), "--nets", candidate.net,
            "--out", str(out)]
    if setup.canyons:
        args += ["--canyons", setup.canyons]
    for setting in candidate.sets:
        args += ["--set", setting]
    return args


def model_names(setup: Setup, candidate: Candidate, size: int) -> list[str]:
    """The model folders a candidate's sweeps train at `size`, one per seed."""
    sweep = widened(
        retarget(get_preset(setup.preset), None, setup.canyons),
        runs=setup.runs,
        subsets=(size,),
        seeds=setup.seeds,
        nets=(candidate.net,),
        grid=tuple(parse_setting(s) for s in candidate.sets),
    )
    return [m.name for m in Sweep.models(sweep)]


def run(out: Path, setup: Setup, candidates: tuple[Candidate, ...] = CANDIDATES) -> int:
    """Every candidate's sweeps (seed-major, so a partial run has whole columns), each evaluation's
    agreement measured as soon as it exists (an interrupted run keeps what it measured)."""
    for seed in setup.seeds:
        for candidate in candidates:
            args = sweep_args(setup, candidate, seed, out)
            print("depthq " + " ".join(args), flush=True)
            if (status := depthq(args)) != 0:
                return status
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
                    done[name] = measure_agreement(folder, Oracle(), out / "probe", predictions=True)
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


def compare(named: list[tuple[str, Path]]) -> str:
    """Markdown: one row per (name, evaluation folder), e.g. a checkpoint driven with `--weights last`."""
    lines = ["| policy | evaluation | to first collision (m) | ends reached /20 | collisions | successes |",
             "|---|---|---|---|---|---|"]
    for name, folder in named:
        s = json.loads((Path(folder) / "summary.json").read_text())["summary"]
        lines.append(f"| {name} | `{Path(folder).name}` | {s['distance_to_collision_mean']:.2f} | "
                     f"{s['reached_end']} | {s['collisions']} | {s['successes']} |")
    return "\n".join(lines)


PATTERN = "eval/{net}_n{n}_s{seed}"  # a sweep's evaluation of a model
PAIRED = (("to first collision (m)", "distance_to_collision_mean", ".2f"), ("successes", "successes", ".1f"),
          ("closest mean (m)", "closest_mean", ".2f"))


def paired_results(sweep: Path, sizes: tuple[int, ...], seeds: tuple[int, ...],
                   pattern: str = PATTERN) -> dict[int, dict[int, list[dict[str, Any]]]]:
    """Per size, per seed with both networks evaluated: [Coll-Q-Net's, Depth-Q-Net's] summary."""
    results: dict[int, dict[int, list[dict[str, Any]]]] = {}
    for n in sizes:
        for seed in seeds:
            found = [Path(sweep) / pattern.format(net=net, n=n, seed=seed) / "summary.json"
                     for net in ("coll", "depth")]
            if all(f.is_file() for f in found):
                results.setdefault(n, {})[seed] = [json.loads(f.read_text())["summary"] for f in found]
    return results


def paired(sweep: Path, sizes: tuple[int, ...], seeds: tuple[int, ...], pattern: str = PATTERN) -> str:
    """Markdown: Depth-Q-Net against Coll-Q-Net trained on the same data with the same seed, per size
    of a sweep folder: each network's mean [95 % interval] and the per-seed difference's (seeds
    trained on the same runs make the comparison a paired one); sizes or seeds not evaluated are left
    out of their row. `pattern` names a model's evaluation folder under `sweep`."""
    lines = ["| runs | seeds | measure | Coll-Q-Net | Depth-Q-Net | Depth − Coll, paired by seed |",
             "|---|---|---|---|---|---|"]
    for n, both in paired_results(sweep, sizes, seeds, pattern).items():
        for label, key, fmt in PAIRED:
            coll, depth = ([float(s[i][key]) for s in both.values()] for i in (0, 1))
            diff = [d - c for c, d in zip(coll, depth, strict=True)]
            cells = [mean_interval(v, fmt) for v in (coll, depth, diff)]
            lines.append(f"| {n} | {','.join(map(str, both))} | {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def paired_evidence(sweep: Path, sizes: tuple[int, ...], seeds: tuple[int, ...],
                    pattern: str = PATTERN) -> dict[str, str]:
    """The paired comparison in words, one sentence per size, keyed by where it was measured
    ('hard/eval, 4 Hz, 500 runs'): the report's evidence for a claim (docs/findings.json)."""
    record = read_json(Path(sweep) / "reproduce.json")["sweep"]
    out = {}
    for n, both in paired_results(sweep, sizes, seeds, pattern).items():
        coll, depth = ([float(s[i]["distance_to_collision_mean"]) for s in both.values()] for i in (0, 1))
        diff = [d - c for c, d in zip(coll, depth, strict=True)]
        ahead = sum(d > 0 for d in diff)
        key = f"{record['canyons']}, {record['decision_hz']:g} Hz, {n} runs"
        out[key] = (f"to the first collision Depth-Q-Net {mean_interval(depth, '.2f')} m, Coll-Q-Net "
                    f"{mean_interval(coll, '.2f')} m; Depth-Q-Net ahead in {ahead} of {len(diff)} seeds "
                    f"(paired difference {mean_interval(diff, '.2f')} m)")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m depthq.experiments.oracle_gap", description=__doc__.split("\n")[0]
    )
    parser.add_argument("action", choices=("run", "table", "compare", "paired"))
    parser.add_argument("out", help="the sweep folder the candidates share (paired: any sweep folder of "
                                    "both networks); compare: NAME=EVAL,NAME=EVAL,…")
    parser.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1")
    parser.add_argument("--sizes", default="500", help="training runs, e.g. 200,500")
    parser.add_argument("--pattern", default=PATTERN,
                        help="paired: a model's evaluation folder under OUT, from {net}, {n} and {seed}")
    parser.add_argument("--claim", help="paired: write the comparison as evidence of this claim of the "
                                        "findings file (e.g. table-i), one entry per size")
    parser.add_argument("--findings", type=Path, default=FINDINGS, help="paired --claim: the findings file")
    args = parser.parse_args(argv)
    return guarded(f"python -m depthq.experiments.oracle_gap {args.action}", lambda: _act(args, argv))


def _act(args: argparse.Namespace, argv: list[str] | None) -> int:
    if args.action == "compare":
        pairs = [item.partition("=") for item in args.out.split(",")]
        print(compare([(name, Path(folder)) for name, _, folder in pairs]))
        return 0
    args.out = Path(args.out)
    setup = Setup(seeds=parse_ints(args.seeds, "--seeds"), sizes=parse_ints(args.sizes, "--sizes"))
    if args.action == "paired":
        print(paired(args.out, setup.sizes, setup.seeds, args.pattern))
        if args.claim:
            command = "python -m depthq.experiments.oracle_gap " + " ".join(argv or sys.argv[1:])
            for key, text in paired_evidence(args.out, setup.sizes, setup.seeds, args.pattern).items():
                record_evidence(args.claim, key, Evidence(text, command), args.findings)
                print(f"{args.findings}: claim {args.claim}, {key}: {text}")
        return 0
    if args.action == "run":
        return run(args.out, setup)
    print(table(args.out, setup))
    return 0


if __name__ == "__main__":
    sys.exit(main())
