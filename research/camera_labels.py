"""Depth-Q-Net on camera labels vs on LiDAR labels vs Coll-Q-Net, per canyon family (issue #32 item 3).

A Depth-Q-Net trained on bins a labeller estimated from the camera (docs/design.md#camera-labels),
against the sweep's own Depth-Q-Net (LiDAR labels) and Coll-Q-Net (the bump), all driven in the same
canyons, per canyon family and labeller.

    python -m research.camera_labels run SWEEP OUT --method floor [--runs 500] [--seeds 0,1]
    python -m research.camera_labels run SWEEP OUT --method monodepth [--runs 500] [--seeds 0,1]
    python -m research.camera_labels run SWEEP OUT --method perception --labeller-data OTHER/data
    python -m research.camera_labels table OUT [OUT2 ...] [--runs 500] [--seeds 0,1]

SWEEP is a `depthq sweep` / `depthq reproduce` folder (SWEEP/data, SWEEP/models/<net>_n<runs>_s<seed>);
OUT holds one sweep's experiment, every labeller's beside the others:

    OUT/setup.json                    the sweep, the canyons, the time limit: what every evaluation here
                                      depends on (another run into OUT must ask the same)
    OUT/<method>/labeller/            the labeller (`depthq labeller --method <method>`)
    OUT/<method>/data/                SWEEP/data hard-linked (labelling rewrites a run file by temporary
                                      file and rename, so SWEEP/data stays as it is), with camera labels
    OUT/<method>/stats.json, .txt     `depthq dataset stats` of it: the labels' error against the LiDAR
    OUT/<method>/models/depth_n<N>_s<S>/  the camera-label Depth-Q-Nets: the sweep's training of that
                                      name (its settings; TrainConfig's defaults where it has none) with
                                      labels "camera", and `--set` on top
    OUT/<method>/eval/depth_n<N>_s<S>/    their evaluations (their own default weights, no video)
    OUT/lidar/eval/<net>_n<N>_s<S>/   the sweep's own Depth-Q-Net and Coll-Q-Net in the same canyons

The labellers: `floor` and `monodepth` (camera and odometry only: learn on the dataset they label,
SWEEP/data by default) and `perception` (learns on ANOTHER canyon family's LiDAR, `--labeller-data`:
a stand-in for an off-the-shelf depth model). Every step is skipped when its output is complete (a
labeller folder with its config.json, runs already labelled, stats.json, a checkpoint at its last
epoch, an evaluation with its summary.json), so the same command resumes. `table` prints the Markdown table;
evaluations of the sweep's models it lacks are driven first. Nothing here pins cores (the caller's
`taskset` does).
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from depthq.checkpoint import CONFIG, read_config, saved_epoch
from depthq.configio import OMIT_DEFAULT, atomic_write_bytes, from_dict, read_json, to_dict, write_json
from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.stats import ERROR_BANDS, error_cell, stats_report
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import SUMMARY, EvalConfig, evaluate, evaluation_done, parse_canyon_set
from depthq.flags import build_config
from depthq.labellers.labeller import (
    CAMERA_METHODS,
    METHODS,
    LabellerConfig,
    label_dataset,
    load_labeller,
    train_labeller,
)
from depthq.labellers.labeller import CONFIG as LABELLER_CONFIG
from depthq.pipeline.layout import model_name
from depthq.pipeline.sweep import parse_ints, parse_setting
from depthq.report.cells import mean_interval
from depthq.sim.canyon import PAPER
from depthq.train.config import TrainConfig
from depthq.train.trainer import train
from research.timing import timed

PROG = "python -m research.camera_labels"
VAL = "val:1000-1019"  # a family's val canyons, far from its datasets' val runs (val:0..89)
# Every evaluation drives each checkpoint's own default weights (a depth-first Depth-Q-Net's final ones,
# Coll-Q-Net's best: docs/design.md), so that no network is weakened for the comparison.
WEIGHTS = None
SETUP = "setup.json"
LIDAR = "lidar"  # OUT/lidar/eval: the sweep's own models, trained on the LiDAR's bins and the bump
REFERENCES = ("depth", "coll")  # the sweep's networks each camera-label Depth-Q-Net is compared with
CRITERION = 0.8  # issue #32: the camera-label net drives ≥ 80 % of the LiDAR-label net's distance
# The labeller settings `run` sets itself: not for --labeller-set.
LABELLER_OWN = ("data", "method")


def val_canyons(family: str) -> str:
    """A family's 20 `val` canyons: 'val:1000-1019' for the paper's, 'hard/val:1000-1019', ..."""
    return VAL if family == PAPER else f"{family}/{VAL}"


@dataclass(frozen=True)
class Setup:
    """What every evaluation in OUT depends on (OUT/setup.json): the sweep whose data and models it
    uses (and its canyon family), the canyons every policy drives and the seconds per run (None: the
    canyons' family's)."""

    sweep: str  # the sweep folder, absolute
    family: str  # the canyon family of its dataset
    canyons: str  # a canyon set, as `depthq evaluate --canyons` takes it
    time_limit_s: float | None = None
    # the look every policy drives in (docs/design.md#looks); none: the canyons' family's own
    look: str | None = field(default=None, metadata=OMIT_DEFAULT)

    def __post_init__(self) -> None:
        self.eval_config()  # a bad canyon set, time limit or look: an error before any work

    def eval_config(self) -> EvalConfig:
        """Each policy once in every canyon, its own default weights, at its data's decision rate."""
        return EvalConfig(canyons=parse_canyon_set(self.canyons), time_limit_s=self.time_limit_s,
                          weights=WEIGHTS, look=self.look)

    def record(self) -> dict[str, Any]:
        return {**to_dict(self), "weights": WEIGHTS}


def claim(out: Path, setup: Setup) -> None:
    """Record `setup` as OUT's, or check it is the one OUT holds (other canyons, another sweep or time
    limit would mix evaluations that cannot be compared: a ConfigError naming the difference)."""
    path = out / SETUP
    if path.is_file():
        held = read_setup(out)
        differ = [f"{k} {getattr(held, k)!r} there, {getattr(setup, k)!r} here"
                  for k in ("sweep", "time_limit_s", "look") if getattr(held, k) != getattr(setup, k)]
        if parse_canyon_set(held.canyons) != parse_canyon_set(setup.canyons):
            differ.append(f"canyons {held.canyons!r} there, {setup.canyons!r} here")
        if differ:
            raise ConfigError(f"{out} holds this experiment with another setup ({'; '.join(differ)}); "
                              "use another OUT")
        return
    write_json(path, setup.record())


def read_setup(out: Path) -> Setup:
    path = Path(out) / SETUP
    if not path.is_file():
        raise ConfigError(f"{out}: not a camera-labels folder (no {SETUP}); make one with `{PROG} run`")
    record = read_json(path)
    return Setup(record["sweep"], record["family"], record["canyons"], record.get("time_limit_s"),
                 record.get("look"))


def link_copy(source: Path, target: Path) -> None:
    """`source` copied to `target` as hard links (`cp -al`; a plain copy across file systems), but for
    its feature caches (labelling changes the runs, so a copy's caches would be stale); into a
    temporary sibling first, so an interrupted copy is never taken for a finished one."""
    if target.exists():
        return
    tmp = target.with_name(f".{target.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)  # an interrupted copy of ours
    shutil.copytree(source, tmp, copy_function=_link, ignore=shutil.ignore_patterns("features"))
    tmp.rename(target)


def _link(src: str, dst: str) -> None:
    try:
        os.link(src, dst)
    except OSError as err:
        if err.errno != errno.EXDEV:
            raise
        shutil.copy2(src, dst)


def write_stats(data: Path, folder: Path) -> dict[str, Any]:
    """`depthq dataset stats` of the labelled copy: folder/stats.json (as `--json` prints it) and
    stats.txt; kept once written."""
    path = folder / "stats.json"
    if path.is_file():
        return read_json(path)
    record, text = stats_report(Dataset.open(data), DataConfig())
    atomic_write_bytes(folder / "stats.txt", (text + "\n").encode())
    write_json(path, record)
    return record


def finished(checkpoint: Path) -> bool:
    """Whether `checkpoint` holds a training at its last epoch."""
    if not (checkpoint / CONFIG).is_file():
        return False
    return saved_epoch(checkpoint) >= int(read_config(checkpoint)["train"]["epochs"])


def camera_config(setup: Setup, data: Path, runs: int, seed: int,
                  settings: tuple[tuple[str, Any], ...] = ()) -> tuple[TrainConfig, str]:
    """The camera-label Depth-Q-Net of (runs, seed): the sweep's own training of that name on `data`
    with labels "camera" (TrainConfig's defaults where the sweep has none), then `settings` (field
    path, value); and where its settings came from, in words."""
    name = model_name("depth", runs, seed)
    lidar = Path(setup.sweep) / "models" / name
    given = {"data": str(data), "labels": "camera", **dict(settings)}
    if (lidar / CONFIG).is_file():
        base = from_dict(TrainConfig, read_config(lidar)["train"])  # of these runs and seed: its name's
        return build_config(TrainConfig, given, base), f"the settings of {lidar}"
    config = build_config(TrainConfig, {"model": "depth", "runs": runs, "seed": seed, **given})
    return config, f"TrainConfig's defaults ({lidar} does not exist)"


def evaluate_once(checkpoint: Path, folder: Path, setup: Setup, workers: int, device: str, progress: bool
                  ) -> None:
    """`checkpoint` driven in the setup's canyons into `folder`, unless done (`evaluation_done`)."""
    if evaluation_done(folder):
        return
    print(f"evaluate {checkpoint} in {setup.canyons} → {folder}", flush=True)
    evaluate(str(checkpoint), folder, setup.eval_config(), workers=workers, progress=progress,
             device=device, video=False)


def evaluate_references(out: Path, setup: Setup, runs: int, seeds: tuple[int, ...], workers: int = 1,
                        device: str = "auto", progress: bool = True) -> None:
    """The sweep's Depth-Q-Nets and Coll-Q-Nets of (runs, seed) driven in the setup's canyons into
    OUT/lidar/eval; a model the sweep has not finished is left out (and said so)."""
    for seed in seeds:
        for net in REFERENCES:
            name = model_name(net, runs, seed)
            checkpoint = Path(setup.sweep) / "models" / name
            if not finished(checkpoint):
                print(f"{checkpoint}: not a finished training; its row is left out", flush=True)
                continue
            evaluate_once(checkpoint, out / LIDAR / "eval" / name, setup, workers, device, progress)


def run(
    sweep: Path,
    out: Path,
    method: str,
    *,
    labeller_data: Path | None = None,
    runs: int = 500,
    seeds: tuple[int, ...] = (0, 1),
    canyons: str | None = None,
    time_limit_s: float | None = None,
    look: str | None = None,
    labeller_settings: tuple[tuple[str, Any], ...] = (),
    training: tuple[tuple[str, Any], ...] = (),
    workers: int = 1,
    device: str = "auto",
    progress: bool = True,
) -> int:
    """The experiment for one labeller `method` on `sweep`'s dataset into OUT (resumed): the labeller,
    the labelled copy and its stats, the camera-label Depth-Q-Nets of `runs` for `seeds` and their
    evaluations, and the sweep's own models' evaluations in the same canyons; then the table."""
    sweep, out = Path(sweep).resolve(), Path(out).resolve()  # checkpoints record their data's path
    if method not in METHODS:
        raise ConfigError(f"--method must be one of {list(METHODS)}, got {method!r}")
    if method == "perception" and labeller_data is None:
        raise ConfigError("--method perception learns on ANOTHER canyon family's LiDAR: give its dataset, "
                          "--labeller-data OTHER_SWEEP/data")
    if own := sorted(set(dict(labeller_settings)) & set(LABELLER_OWN)):
        raise ConfigError(f"--labeller-set {', '.join(own)}: set by --method and --labeller-data")
    if "labels" in dict(training):
        raise ConfigError("--set labels: the Depth-Q-Nets here learn from camera labels")
    family = Dataset.open(sweep / "data").family()
    if family is None:
        raise ConfigError(f"{sweep / 'data'}: a robot's recording has no canyons to drive in")
    setup = Setup(str(sweep), family, canyons or val_canyons(family), time_limit_s, look)
    learn_on = str(Path(labeller_data or sweep / "data").resolve())
    if method == "perception" and Dataset.open(Path(learn_on)).family() == family:
        raise ConfigError(f"--labeller-data {learn_on} is of the {family!r} family too: a perception "
                          "labeller learns on another family's LiDAR (no depth of these canyons goes in)")
    labeller_config = build_config(LabellerConfig,
                                   {"data": learn_on, "method": method, **dict(labeller_settings)})
    configs = [camera_config(setup, out / method / "data", runs, seed, training) for seed in seeds]
    out.mkdir(parents=True, exist_ok=True)
    claim(out, setup)
    folder = out / method
    if not (folder / "labeller" / LABELLER_CONFIG).is_file():
        print(f"labeller {method}: learn on {labeller_config.data} → {folder / 'labeller'}", flush=True)
    with timed(folder, "labeller", done=(folder / "labeller" / LABELLER_CONFIG).is_file()):
        labeller = train_labeller(labeller_config, folder / "labeller", progress=progress, device=device)
    with timed(folder, "labels", done=(folder / "stats.json").is_file()):  # written once labelled
        link_copy(sweep / "data", folder / "data")
        written, _ = label_dataset(Dataset.open(folder / "data"), load_labeller(labeller), progress=progress)
    if written:
        print(f"{folder / 'data'}: camera labels written in {written} runs", flush=True)
    write_stats(folder / "data", folder)
    for config, origin in configs:
        name = model_name("depth", runs, config.seed)
        checkpoint = folder / "models" / name
        if not finished(checkpoint):
            print(f"train {checkpoint}: camera labels, {origin}", flush=True)
        with timed(folder, f"train {name}", done=finished(checkpoint)):
            train(config, checkpoint, progress=progress, device=device)
        evaluate_once(checkpoint, folder / "eval" / name, setup, workers, device, progress)
    evaluate_references(out, setup, runs, seeds, workers, device, progress)
    print(table([out], runs, seeds, evaluate_missing=False))
    return 0


def _summaries(folder: Path, runs: int, seeds: tuple[int, ...], net: str = "depth") -> dict[int, dict]:
    """seed → summary of the evaluations under `folder` (an `eval` folder) that have finished."""
    found = {}
    for seed in seeds:
        path = folder / model_name(net, runs, seed) / SUMMARY
        if path.is_file():
            found[seed] = read_json(path)["summary"]
    return found


def error_cells(stats: dict[str, Any] | None) -> list[str]:
    """The labels' error on the training runs (the labels the Depth-Q-Nets learn from): nearest bin,
    then each LiDAR distance band, median [mean] m."""
    split = ((stats or {}).get("camera_labels") or {}).get("splits", {}).get("train")
    if split is None:
        return ["–"] * (1 + len(ERROR_BANDS))
    return [error_cell(split["nearest"]), *(error_cell(b) for b in split["bands"])]


def read_stats(folder: Path) -> dict[str, Any] | None:
    """OUT/<method>/stats.json (`write_stats`); None before it is written."""
    path = folder / "stats.json"
    return read_json(path) if path.is_file() else None


def _labeller_name(folder: Path) -> str:
    path = folder / "labeller" / LABELLER_CONFIG
    if not path.is_file():
        return folder.name
    record = read_json(path)
    if record["name"] in CAMERA_METHODS:
        return f"{record['name']} (camera + odometry)"
    return f"perception (learnt on the {record['source']['family']} family's LiDAR)"


def _row(cells: list[Any]) -> str:
    return "| " + " | ".join(map(str, cells)) + " |"


def table(
    outs: list[Path], runs: int = 500, seeds: tuple[int, ...] = (0, 1), *, evaluate_missing: bool = True,
    workers: int = 1, device: str = "auto", progress: bool = True,
) -> str:
    """Markdown: per experiment folder (a sweep's canyon family) and labeller, the camera labels' error
    against the LiDAR (median [mean] m, on the training runs: nearest bin, then per LiDAR distance
    band), and per Q-net the distance to the first collision per seed and its mean [95 % interval],
    ends reached and collisions per seed; the camera-label Depth-Q-Net's mean distance as a share of
    the LiDAR-label one's over the seeds both have (issue #32's criterion: ≥ 80 %). With
    `evaluate_missing`, evaluations of the sweep's models not yet in OUT/lidar are driven first."""
    bands = [f"{low:g}–{high:g} m" for low, high in ERROR_BANDS]
    lines = [
        _row(["family (sweep)", "canyons", "Q-net, labels", "labels' error, nearest bin (m)", *bands, "seeds",
              "to first collision (m), per seed", "to first collision (m), mean", "ends reached, per seed",
              "collisions, per seed", f"camera / LiDAR distance (≥ {CRITERION:.0%})"]),
        _row(["---"] * (10 + len(bands))),
    ]
    for out in map(Path, outs):
        setup = read_setup(out)
        if evaluate_missing:
            evaluate_references(out, setup, runs, seeds, workers, device, progress)
        where = [f"{setup.family} (`{Path(setup.sweep).name}`)", setup.canyons]
        lidar, none = _summaries(out / LIDAR / "eval", runs, seeds), error_cells(None)
        rows = [(f"Depth-Q-Net, camera labels: {_labeller_name(out / m)}",
                 _summaries(out / m / "eval", runs, seeds), error_cells(read_stats(out / m)), True)
                for m in METHODS if (out / m).is_dir()]
        rows += [("Depth-Q-Net, LiDAR labels", lidar, none, False),
                 ("Coll-Q-Net", _summaries(out / LIDAR / "eval", runs, seeds, "coll"), none, False)]
        for name, found, errors, camera in rows:
            d2c = [s["distance_to_collision_mean"] for s in found.values()]
            ratio = "–"
            both = sorted(set(found) & set(lidar))
            if camera and both:
                share = (np.mean([found[s]["distance_to_collision_mean"] for s in both])
                         / np.mean([lidar[s]["distance_to_collision_mean"] for s in both]))
                ratio = f"{share:.0%} {'✓' if share >= CRITERION else '✗'}"
            per_seed = [", ".join(f"{s[key]:{fmt}}" for s in found.values()) or "–"
                        for key, fmt in (("distance_to_collision_mean", ".2f"), ("reached_end", "d"),
                                         ("collisions", "d"))]
            lines.append(_row([*where, f"{name}, {runs} runs", *errors, ",".join(map(str, found)) or "–",
                               per_seed[0], mean_interval(d2c, ".2f", len(seeds)), per_seed[1], per_seed[2],
                               ratio]))
    return "\n".join(lines)


def parse_settings(items: list[str], what: str) -> tuple[tuple[str, Any], ...]:
    """'field=value' items (one value each) as (field path, value) pairs; a training's through
    `depthq sweep --set`'s parser (its checks and names)."""
    out = []
    for item in items:
        if what == "--set":
            key, values = parse_setting(item)
            if len(values) != 1:
                raise ConfigError(f"--set {item!r}: one value per setting here")
            out.append((key, values[0]))
            continue
        key, sep, raw = item.partition("=")
        if not sep or not raw:
            raise ConfigError(f"{what} takes FIELD=VALUE, got {item!r}")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw  # a word, e.g. a trunk's name
        out.append((key.strip().replace("-", "_"), value))
    return tuple(out)


def main(argv: list[str] | None = None) -> int:
    description = (__doc__.split("\n")[0] + " Choose on `val` canyons (the default) or a fresh stream; "
                   "the `eval` canyons are for the final table only.")
    parser = argparse.ArgumentParser(prog=PROG, description=description)
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    canyons_help = ("the canyon set every policy drives, as `depthq evaluate --canyons` takes it (default: "
                    f"the sweep's family's {VAL}); choose on `val` canyons or a fresh stream "
                    "('stream7:0-19'): the `eval` canyons are for the final table only")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--runs", type=int, default=500, help="training runs of every Q-net (default: 500)")
    common.add_argument("--seeds", default="0,1", help="training seeds, e.g. 0,1 or 0-2 (default: 0,1)")
    common.add_argument("--workers", type=int, default=1, help="processes per evaluation (default: 1)")
    common.add_argument("--device", default="auto", help="torch device of training and evaluation "
                                                          "(default: auto)")
    common.add_argument("--no-progress", action="store_true", help="no progress bars")
    go = actions.add_parser("run", parents=[common], description=description,
                            help="labeller, labels, stats, camera-label Depth-Q-Nets, evaluations (resumed)")
    go.add_argument("sweep", type=Path, help="a sweep folder (`depthq sweep` / `depthq reproduce`)")
    go.add_argument("out", type=Path, help="this sweep's experiment folder (created; resumed)")
    go.add_argument("--method", required=True, choices=METHODS,
                    help="floor, monodepth: camera and odometry only, learnt on the dataset it labels; "
                         "perception: learnt on another canyon family's LiDAR (--labeller-data)")
    go.add_argument("--labeller-data", type=Path, default=None,
                    help="the dataset the labeller learns on: perception, ANOTHER family's (e.g. "
                         "OTHER_SWEEP/data); floor, monodepth: default SWEEP/data")
    go.add_argument("--canyons", default=None, help=canyons_help)
    go.add_argument("--time-limit", type=float, default=None,
                    help="seconds per evaluation run (default: the canyons' family's)")
    go.add_argument("--look", default=None,
                    help="the look every policy drives in: flat, colours, textured, heldout, broad or a "
                         "folder of images (default: the canyons' family's own)")
    go.add_argument("--labeller-set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a LabellerConfig setting (e.g. steps=300, pool_runs=100); repeatable")
    go.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a training setting over the sweep's (e.g. epochs=20), as `depthq sweep --set` "
                         "takes it, one value; repeatable")
    show = actions.add_parser("table", parents=[common], help="the Markdown table (drives the sweep's "
                              "models' missing evaluations first)", description=description)
    show.add_argument("outs", type=Path, nargs="+", metavar="OUT",
                      help="experiment folders of `run` (each knows its sweep and canyons)")
    args = parser.parse_args(argv)

    def work() -> int:
        seeds = parse_ints(args.seeds, "--seeds")
        if args.action == "run":
            return run(args.sweep, args.out, args.method, labeller_data=args.labeller_data, runs=args.runs,
                       seeds=seeds, canyons=args.canyons, time_limit_s=args.time_limit, look=args.look,
                       labeller_settings=parse_settings(args.labeller_set, "--labeller-set"),
                       training=parse_settings(args.set, "--set"), workers=args.workers, device=args.device,
                       progress=not args.no_progress)
        print(table(args.outs, args.runs, seeds, workers=args.workers, device=args.device,
                    progress=not args.no_progress))
        return 0

    return guarded(f"{PROG} {args.action}", work)


if __name__ == "__main__":
    sys.exit(main())
