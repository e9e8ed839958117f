"""DAgger with a self-supervised target (docs/oracle_gap.md#dagger): rounds of collection driven by the
learned Depth-Q-Net (the exploration's OU command added to its action), each run's targets, as every
run's, the depth that follows (no collision needed), aggregated with the exploration runs at the
baseline's number of training runs; the other network is offered the same aggregate. With `--net
coll` Coll-Q-Net drives its own rounds (its target needs the collisions its runs end in).

    python -m research.dagger run OUT --base DATA [--net depth] [--seeds 0,1] [--rounds 2]
    python -m research.dagger table OUT [--net depth] [--seeds 0,1] [--baseline SWEEP]
    python -m research.dagger stats OUT [--seeds 0,1]

With `runs` = N training runs in all and R rounds of M runs, round 0 is the network trained on the
base's first N − R·M usable runs; round r drives the next training canyons (from the one after round
r − 1's last), with the noise seeds the base's runs there had, by round r − 1's model until it has M
usable runs (as `depthq collect` goes on past runs under min_frames frames), and trains on all so
far: as many usable runs as the baseline's. Layout of OUT:

    OUT/s<seed>/round<r>/data     round r's dataset: the base's runs it keeps and all its `val` runs
                                  (hard links), and the runs of rounds 1 … r; its manifest's config is
                                  the base's plus `rounds` (each round's driver, noise and first run)
    OUT/s<seed>/round<r>/model    the network trained on it (round 0: on the base's runs alone)
    OUT/s<seed>/<other>           the other network (coll or depth) trained on the last round's data
    OUT/s<seed>/eval/<model>      each model driven in the `val` canyons (round0 … roundR, <other>)

Every step resumes: a dataset's runs are recorded one by one, a training from its last epoch, an
evaluation is kept once its summary is written. The `eval` canyons are never driven here.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/oracle_gap.md#dagger came from the code of commit a77c1cf (2026-11-26: the last change of that
page's tables).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from depthq.checkpoint import saved_epoch
from depthq.configio import from_dict
from depthq.data.manifest import Dataset
from depthq.data.recorder import CollectConfig, collect_and_write
from depthq.data.samples import SampleConfig, usable
from depthq.data.subsets import select_runs
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import evaluate
from depthq.pipeline.presets import get_preset
from depthq.pipeline.sweep import Model, Sweep, parse_ints, retarget, widened
from depthq.policies.registry import make_policy
from depthq.report.cells import evaluation_summary, mean_interval
from depthq.sim.env import CanyonEnv
from depthq.train.trainer import train

NAMES = {"depth": "Depth-Q-Net", "coll": "Coll-Q-Net"}


@dataclass(frozen=True)
class Setup:
    """The rounds: the baseline's dataset, preset and `val` canyons, how many runs in all and per round."""

    base: str  # the baseline's dataset folder (exploration runs); holds at least `runs` usable ones
    preset: str = "hard"
    canyons: str = "hard/val:1000-1019"
    runs: int = 500  # training runs in all, as many as the baseline's
    rounds: int = 2
    round_runs: int = 100  # runs per round, each driven by the previous round's model
    noise: float = 1.0  # the OU command added to the policy's, as a multiple of the exploration's
    seeds: tuple[int, ...] = (0,)
    net: str = "depth"  # the network whose policy drives the rounds
    time_limit_s: float | None = None  # seconds per evaluation run; None: the canyons' family's

    def __post_init__(self) -> None:
        for name in ("runs", "rounds", "round_runs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                flag = name.replace("_", "-")
                raise ConfigError(f"dagger: --{flag} must be an integer >= 1, got {value!r}")
        if self.rounds * self.round_runs >= self.runs:
            raise ConfigError(f"dagger: {self.rounds} rounds of {self.round_runs} runs leave no exploration "
                              f"runs of {self.runs} for round 0")
        if not 0 <= self.noise < float("inf"):
            raise ConfigError(f"dagger: --noise must be a finite number >= 0, got {self.noise!r}")
        if self.net not in NAMES:
            raise ConfigError(f"dagger: --net must be one of {tuple(NAMES)}, got {self.net!r}")

    @property
    def other(self) -> str:
        """The network offered the last round's data."""
        return next(name for name in NAMES if name != self.net)

    @property
    def first(self) -> int:
        """The base's runs round 0 trains on."""
        return self.runs - self.rounds * self.round_runs


def sweep_of(setup: Setup, seed: int, net: str) -> Sweep:
    """The preset's sweep for one network and seed in the setup's canyons: its training settings
    and evaluation."""
    limit = () if setup.time_limit_s is None else (("time_limit_s", setup.time_limit_s),)
    return widened(retarget(get_preset(setup.preset), None, setup.canyons), runs=setup.runs,
                   name=f"{setup.preset} dagger", subsets=(setup.runs,), seeds=(seed,), nets=(net,),
                   evaluate=limit)


def base_indices(base: Dataset, setup: Setup) -> list[int]:
    """The training-run indices of the base's first `runs` usable runs (the baseline's data); a
    ConfigError if it has fewer."""
    return [e.index for e in select_runs(base, "train", setup.runs, int(base.config["data"]["min_frames"]))]


def _link(source: Path, target: Path) -> None:
    """`target` as a hard link of `source` (a copy across file systems); run files are never rewritten
    in place, so the two never diverge."""
    target.parent.mkdir(parents=True, exist_ok=True)
    target.unlink(missing_ok=True)
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def round_data(folder: Path, base: Dataset, setup: Setup, r: int) -> Dataset:
    """Round r's dataset (r ≥ 1), collected or resumed: round r − 1's runs (round 1: the base's first
    runs and its `val` runs) linked, then round r's driven by round r − 1's model."""
    min_frames = int(base.config["data"]["min_frames"])
    if r == 1:
        last = base_indices(base, setup)[setup.first - 1]
        previous, kept = base, [e for e in base.entries() if e.split == "val" or e.index <= last]
    else:
        previous = Dataset.open(folder / f"round{r - 1}" / "data")
        kept, last = previous.entries(), previous.entries("train")[-1].index
    rounds = [*previous.config.get("rounds", []),
              {"round": r, "driver": f"round{r - 1}/model", "noise": setup.noise, "first": last + 1}]
    dataset = Dataset.create(folder / f"round{r}" / "data", {**base.config, "rounds": rounds}, base.seed)
    for entry in kept:
        if not dataset.has(entry.split, entry.index):
            _link(previous.path(entry), dataset.run_path(entry.split, entry.index))
            dataset.add(entry.run_meta(), entry.info)
    done = sum(usable(e, min_frames) for e in dataset.entries("train") if e.index > last)
    if done >= setup.round_runs:
        return dataset
    collect = from_dict(CollectConfig, {**base.config, "seed": base.seed})
    collect = replace(collect, ou=replace(collect.ou, scale=collect.ou.scale * setup.noise))
    driver = make_policy(str(folder / f"round{r - 1}" / "model"), device="cpu")
    env, index = CanyonEnv(collect.env), last + 1
    bar = tqdm(total=setup.round_runs, initial=done, desc=f"round {r}: collect", unit="usable run",
               dynamic_ncols=True)
    try:
        while done < setup.round_runs:
            if not dataset.has("train", index):  # a resumed round's runs are counted in `done` already
                meta, info = collect_and_write(env, collect, base.seed, dataset.root, "train", index, driver)
                added = usable(dataset.add(meta, info), min_frames)
                done += added
                bar.update(added)
            index += 1
    finally:
        bar.close()
        env.close()
    return dataset


def _train(setup: Setup, seed: int, net: str, data: Path, runs: int | None, folder: Path) -> None:
    """The preset's `net` trained on `data` (its first `runs` usable runs; None: all) into `folder`."""
    config = sweep_of(setup, seed, net).train_config(Model(net, setup.runs, seed), str(data))
    config = replace(config, runs=runs)
    if saved_epoch(folder) < config.epochs:
        train(config, folder)


def _evaluate(setup: Setup, seed: int, model: Path, out: Path) -> None:
    if not (out / "summary.json").is_file():
        evaluate(str(model), out, sweep_of(setup, seed, setup.net).eval_config(), workers=1, video=False)


def run(out: Path, setup: Setup) -> int:
    """Every seed's rounds, then the other network on the last round's data; each model driven in the
    canyons."""
    base, other = Dataset.open(Path(setup.base)), setup.other
    for seed in setup.seeds:
        folder = out / f"s{seed}"
        _train(setup, seed, setup.net, base.root, setup.first, folder / "round0" / "model")
        _evaluate(setup, seed, folder / "round0" / "model", folder / "eval" / "round0")
        for r in range(1, setup.rounds + 1):
            data = round_data(folder, base, setup, r)
            _train(setup, seed, setup.net, data.root, None, folder / f"round{r}" / "model")
            _evaluate(setup, seed, folder / f"round{r}" / "model", folder / "eval" / f"round{r}")
        _train(setup, seed, other, folder / f"round{setup.rounds}" / "data", None, folder / other)
        _evaluate(setup, seed, folder / other, folder / "eval" / other)
    print(table(out, setup))
    return 0


def table(out: Path, setup: Setup, baseline: Path | None = None) -> str:
    """Markdown: each model's distance to the first collision (mean over seeds, 95 % interval with 2 or
    more) and ends reached, per round; with `baseline` (a sweep folder of the base's data) the
    exploration-only models at `runs` beside them."""
    rows = [(f"{NAMES[setup.net]}, round {r}" + (" (exploration runs only)" if r == 0 else ""),
             [out / f"s{s}" / "eval" / f"round{r}" for s in setup.seeds]) for r in range(setup.rounds + 1)]
    rows.append((f"{NAMES[setup.other]} on round {setup.rounds}'s data",
                 [out / f"s{s}" / "eval" / setup.other for s in setup.seeds]))
    if baseline is not None:
        rows += [(f"{name}, {setup.runs} exploration runs (baseline)",
                  [baseline / "eval" / f"{net}_n{setup.runs}_s{s}" for s in setup.seeds])
                 for net, name in NAMES.items()]
    lines = ["| model | seeds | to first collision (m) | ends reached /20 |", "|---|---|---|---|"]
    for name, folders in rows:
        found = [s for s in map(evaluation_summary, folders) if s is not None]
        if found:
            ends = sum(s["reached_end"] for s in found) / len(found)
            d2c = [s["distance_to_collision_mean"] for s in found]
            lines.append(f"| {name} | {len(found)} | {mean_interval(d2c, '.2f')} | {ends:.1f} |")
    return "\n".join(lines)


NEAR = 0.5  # m: a frame whose nearest depth bin is closer than this is "near an obstacle"


def stats(out: Path, setup: Setup) -> str:
    """Markdown: what each round adds to the last round's dataset, per seed, counting the usable runs
    (those trained on): runs, frames per run, runs ending in a collision, the mean |command| (as the
    samples clip it), the share of commands at that clip, and the share of frames near an obstacle."""
    lines = ["| seed | runs of | usable runs | frames per run | end in a collision | mean abs. command | "
             "commands at the clip | frames with a bin < 0.5 m |", "|---|---|---|---|---|---|---|---|"]
    for seed in setup.seeds:
        dataset = Dataset.open(out / f"s{seed}" / f"round{setup.rounds}" / "data")
        # the samples' clip (a training setting; manifests before #48 recorded it too) and which runs count
        clip = float(dataset.config["data"].get("action_clip", SampleConfig().action_clip))
        min_frames = int(dataset.config["data"]["min_frames"])
        firsts = [0] + [r["first"] for r in dataset.config["rounds"]]
        for r, (lo, hi) in enumerate(zip(firsts, [*firsts[1:], float("inf")], strict=True)):
            entries = [e for e in dataset.entries("train") if lo <= e.index < hi and usable(e, min_frames)]
            runs = [dataset.read_run(e, images=False) for e in entries]
            actions = np.abs(np.clip(np.concatenate([run.actions[:-1] for run in runs]), -clip, clip))
            nearest = np.concatenate([np.nanmin(run.bins, axis=1) for run in runs])
            lines.append(
                f"| {seed} | {'exploration' if r == 0 else f'round {r}'} | {len(runs)} | "
                f"{np.mean([run.meta.n_frames for run in runs]):.1f} | "
                f"{np.mean([run.meta.collision for run in runs]):.0%} | {actions.mean():.2f} | "
                f"{np.mean(actions >= clip - 1e-6):.0%} | {np.mean(nearest < NEAR):.0%} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.dagger",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("action", choices=("run", "table", "stats"))
    parser.add_argument("out", type=Path, help="the experiment's folder")
    parser.add_argument("--base", default="", help="run: the baseline's dataset folder (exploration runs)")
    parser.add_argument("--preset", default=Setup.preset, help="whose training settings and canyons' family")
    parser.add_argument("--canyons", default=Setup.canyons, help="where each model is driven (val canyons)")
    parser.add_argument("--runs", type=int, default=Setup.runs, help="training runs in all")
    parser.add_argument("--rounds", type=int, default=Setup.rounds,
                        help="rounds driven by the learned policy")
    parser.add_argument("--round-runs", type=int, default=Setup.round_runs, help="runs per round")
    parser.add_argument("--noise", type=float, default=Setup.noise,
                        help="the OU command added to the policy's, as a multiple of the exploration's")
    parser.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1")
    parser.add_argument("--net", default=Setup.net, help="the network whose policy drives the rounds: "
                                                         "depth or coll")
    parser.add_argument("--time-limit", type=float, help="seconds per evaluation run (default: the "
                                                         "canyons' family's)")
    parser.add_argument("--baseline", type=Path, help="table: a sweep folder of the base's data, its "
                                                      "exploration-only models shown beside")
    args = parser.parse_args(argv)

    def act() -> int:
        if args.action == "run" and not args.base:
            raise ConfigError("dagger run: --base DATA (the baseline's dataset folder) is required")
        setup = Setup(args.base, args.preset, args.canyons, args.runs, args.rounds, args.round_runs,
                      args.noise, parse_ints(args.seeds, "--seeds"), args.net, args.time_limit)
        if args.action == "run":
            return run(args.out, setup)
        if args.action == "stats":
            print(stats(args.out, setup))
            return 0
        print(table(args.out, setup, args.baseline))
        return 0

    return guarded(f"python -m research.dagger {args.action}", act)


if __name__ == "__main__":
    sys.exit(main())
