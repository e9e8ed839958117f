"""Looks (docs/design.md#looks): the same pose in every look, and which value signal transfers across
looks (issue #45 item 3).

    python -m depthq.experiments.looks figure [DOCS]          # DOCS/looks.png (default docs/)
    python -m depthq.experiments.looks run OUT [--runs 500] [--seeds 0-2] [--canyons hard/eval]
    python -m depthq.experiments.looks table OUT [--runs 500] [--seeds 0-2]

`run` (resumed: every step is skipped when its output is complete), per training look L (default
colours, textured), hard canyons:

    OUT/<L>/sweep/             `depthq sweep --preset hard --look L --runs N --sizes N --seeds S
                               --canyons <choose>`: the data in look L, the Depth-Q-Nets (LiDAR labels)
                               and Coll-Q-Nets, evaluated in look L in the choice canyons
    OUT/<L>/camera/            `python -m depthq.experiments.camera_labels run` on it (--method
                               monodepth): the labeller, its labels' error, the camera-label Depth-Q-Nets
    OUT/<L>/eval_<D>/<net>_s<S>/  every net (depth, camera, coll) driven in look D (default colours,
                               textured, heldout) in `--canyons`

`table` prints, per net and training look, the distance to the first collision (mean [95 %
interval] over seeds) in each driving look, and each look's share of the training look's.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.experiments import camera_labels
from depthq.flags import build_config
from depthq.labellers.labeller import LabellerConfig
from depthq.nets.checkpoint import CONFIG
from depthq.pipeline.layout import model_name
from depthq.pipeline.presets import get_preset
from depthq.pipeline.runner import run_sweep
from depthq.pipeline.sweep import Model, Settings, Sweep, parse_ints, retarget, widened
from depthq.report.build import build_report
from depthq.report.cells import evaluation_summary, mean_interval
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.look import COLOURS, HELDOUT, LOOKS, TEXTURED, check_look
from depthq.sim.world import WorldConfig, world_for
from depthq.train.config import TrainConfig

PROG = "python -m depthq.experiments.looks"
CANYON = "hard/val:1000"  # the figure's: a val canyon (the docs show no test canyon)
POSE_STEPS = 8  # straight ahead for this many decisions, then one turning step (blur in the textured looks)
TRAIN_LOOKS = (COLOURS, TEXTURED)
DRIVE_LOOKS = (COLOURS, TEXTURED, HELDOUT)
CHOOSE = "hard/val:1000-1019"  # where the sweep and the camera-label experiment make their choices
NETS = {"depth": "Depth-Q-Net, LiDAR labels", "camera": "Depth-Q-Net, camera labels", "coll": "Coll-Q-Net"}

# Every setting the experiment's nets train with (TrainConfig field paths; "lr" the effective rate),
# as the `hard` preset and the defaults of commit 0ab0c20 gave them, where the run behind
# docs/design.md#looks started. `run` gives every training the pinned values today's preset and
# defaults no longer hold (none on that commit), so the documented command trains the same nets on a
# later commit. The camera-label Depth-Q-Net trains as the LiDAR one (`camera_labels.camera_config`),
# on camera labels.
_PINNED_DEPTH: dict[str, Any] = {
    "epochs": 40, "train_batches": 100, "val_batches": 10, "batch_size": 64, "lr": 0.1, "rho": 0.95,
    "eps": 1e-08, "weight_decay": 4e-05, "trunk": "efficientnet_lite0_columns", "dropout": 0.0,
    "action_scale": 10.0, "input_size": 128, "depth_loss": "original", "lookahead": 1,
    "lookahead_discount": 1.0, "feature_projection": 0, "hidden": 4096, "head_form": "depth_first",
    "output_bias": 0.0, "bootstrap": 0.0, "mirror": False, "labels": "lidar", "samples.horizon": 5,
    "samples.min_frames": 20, "samples.every_run_end": True, "samples.action_clip": 1.0,
    "samples.action_lag": 0, "weights": "average", "snapshots": [], "average": 0.25, "precision": "fp32",
}
PINNED_TRAINING: dict[str, dict[str, Any]] = {
    "depth": _PINNED_DEPTH,
    "coll": {**_PINNED_DEPTH, "head_form": "concat", "weights": "best", "average": 0.0},  # every field
}
# The monodepth labeller's settings (LabellerConfig, besides its data and method), pinned as above.
PINNED_LABELLER: dict[str, Any] = {
    "trunk": "efficientnet_lite0_columns", "input_size": 128, "hidden": 4096, "scale": 4, "width": 16,
    "context": True, "lookahead": 12, "nearest": 0.3, "memory_s": 2.0, "pool_frames": 6, "pool_runs": 300,
    "min_depth": 0.1, "max_depth": 10.0, "smoothness": 0.001, "steps": 1500, "batch_size": 8, "lr": 0.001,
    "seed": 0,
}
PINNED_PRESET, PINNED_METHOD = "hard", "monodepth"  # another preset or labeller trains as it does today


_GONE = object()


def _flat(config: Any, prefix: str = "") -> dict[str, Any]:
    """A config's fields by path ('samples.horizon'), JSON values; a training's "lr" its effective rate."""
    values = json.loads(json.dumps(asdict(config))) if not isinstance(config, dict) else config
    out: dict[str, Any] = {}
    for key, value in values.items():
        out.update(_flat(value, f"{prefix}{key}.") if isinstance(value, dict) else {prefix + key: value})
    if isinstance(config, TrainConfig):
        out["lr"] = config.learning_rate
    return out


def _restoring(pins: dict[str, dict[str, Any]], built: dict[str, dict[str, Any]],
               given: set[str]) -> tuple[tuple[str, Any], ...]:
    """The settings (field path, value) that bring each built config back to its pin, but for the
    fields `given` on the command line; every config takes them all (a sweep's settings are every
    net's), so a setting must suit each pin."""
    needed: dict[str, Any] = {}
    for name, pin in pins.items():
        for key, value in pin.items():
            if key not in given and built[name].get(key, _GONE) != value:  # gone: build_config names it
                needed[key] = value
    for key, value in needed.items():
        if clash := [name for name, pin in pins.items() if pin[key] != value]:
            raise ConfigError(f"the defaults moved away from the looks experiment's pinned {key} differently "
                              f"for {', '.join(clash)}: pin that setting per network in "
                              f"depthq.experiments.looks")
    return tuple(needed.items())


def pinned_training(sweep: Sweep, runs: int, seed: int, given: Settings, preset: str = PINNED_PRESET
                    ) -> Settings:
    """`given` (the command's --set), after the pinned settings today's defaults no longer hold (for
    the pinned preset's sweep)."""
    if preset != PINNED_PRESET:
        return tuple(given)
    built = {net: _flat(sweep.train_config(Model(net, runs, seed), "data")) for net in PINNED_TRAINING}
    return _restoring(PINNED_TRAINING, built, set(dict(given))) + tuple(given)


def pinned_labeller(method: str, given: Settings) -> Settings:
    """`given` (the command's --labeller-set), after the pinned labeller settings today's defaults no
    longer hold (for the pinned method; another method's labeller is today's)."""
    if method != PINNED_METHOD:
        return tuple(given)
    built = _flat(build_config(LabellerConfig, {"data": ".", "method": method}))
    return _restoring({method: PINNED_LABELLER}, {method: built}, set(dict(given))) + tuple(given)


def frames(canyon: str = CANYON, looks: tuple[str, ...] = LOOKS) -> dict[str, np.ndarray]:
    """Each look's camera frame after the same drive (seed 0) into `canyon`."""
    out = {}
    for look in looks:
        family = "hard" if canyon.startswith("hard/") else "paper"
        world = replace(world_for(WorldConfig(), family), look=look)
        env = CanyonEnv(EnvConfig(world=world))
        try:
            obs, _ = env.reset(seed=0, options={"canyon": canyon})
            for action in [0.0] * POSE_STEPS + [0.8]:
                obs, *_ = env.step(np.array([action], np.float32))
            out[look] = obs["image"].copy()
        finally:
            env.close()
    return out


def figure(path: Path, canyon: str = CANYON) -> None:
    """A 2 × 2 grid of the looks' frames, each labelled, as a PNG."""
    tiles = []
    for look, image in frames(canyon).items():
        tile = Image.fromarray(image)
        ImageDraw.Draw(tile).text((8, 6), look, fill=(255, 255, 255))
        tiles.append(np.asarray(tile))
    half = (len(tiles) + 1) // 2
    grid = np.concatenate([np.concatenate(tiles[:half], 1), np.concatenate(tiles[half:], 1)], 0)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(grid).save(path)


def checkpoints(out: Path, look: str, runs: int, seed: int, method: str) -> dict[str, Path]:
    """The nets trained in `look`: the sweep's Depth-Q-Net and Coll-Q-Net, the camera-label Depth-Q-Net."""
    name = model_name("depth", runs, seed)
    return {"depth": out / look / "sweep" / "models" / name,
            "camera": out / look / "camera" / method / "models" / name,
            "coll": out / look / "sweep" / "models" / model_name("coll", runs, seed)}


def run(out: Path, *, preset: str = "hard", runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
        canyons: str = "hard/eval", choose: str = CHOOSE, train_looks: tuple[str, ...] = TRAIN_LOOKS,
        drive_looks: tuple[str, ...] = DRIVE_LOOKS, method: str = "monodepth",
        time_limit_s: float | None = None,
        labeller_settings: tuple[tuple[str, Any], ...] = (), training: tuple[tuple[str, Any], ...] = (),
        workers: int = 2, device: str = "auto", progress: bool = True) -> int:
    """The experiment into OUT (resumed); then its table."""
    out = Path(out).resolve()
    for look in (*train_looks, *drive_looks):
        check_look(look)
    driving = EvalConfig(canyons=parse_canyon_set(canyons), time_limit_s=time_limit_s)  # checked up front
    for look in train_looks:
        sweep = retarget(get_preset(preset), family="hard", canyons=choose, look=look)
        if time_limit_s is not None:
            limit = {**dict(sweep.evaluate), "time_limit_s": time_limit_s}
            sweep = replace(sweep, evaluate=tuple(limit.items()))
        sweep = widened(sweep, runs, subsets=(runs,), seeds=seeds, name=f"{preset} in the {look} look")
        pinned = pinned_training(sweep, runs, seeds[0], training, preset)
        sweep = replace(sweep, train=tuple({**dict(sweep.train), **dict(pinned)}.items()))
        print(f"sweep in the {look} look → {out / look / 'sweep'}", flush=True)
        run_sweep(sweep, out / look / "sweep", progress=progress, device=device, finish=build_report)
        camera_labels.run(out / look / "sweep", out / look / "camera", method, runs=runs, seeds=seeds,
                          canyons=choose, time_limit_s=time_limit_s, look=look,
                          labeller_settings=pinned_labeller(method, labeller_settings),
                          training=tuple((k, v) for k, v in pinned if k != "labels"),  # camera's own
                          workers=workers,
                          device=device, progress=progress)
        for drive in drive_looks:
            config = replace(driving, look=drive)
            for seed in seeds:
                for net, checkpoint in checkpoints(out, look, runs, seed, method).items():
                    folder = out / look / f"eval_{drive}" / f"{net}_s{seed}"
                    if (folder / "summary.json").is_file() or not (checkpoint / CONFIG).is_file():
                        continue
                    print(f"evaluate {checkpoint} in the {drive} look → {folder}", flush=True)
                    evaluate(str(checkpoint), folder, config, workers=workers, progress=progress,
                             device=device, video=False)
    print(table(out, runs, seeds, train_looks, drive_looks))
    return 0


def table(out: Path, runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
          train_looks: tuple[str, ...] = TRAIN_LOOKS, drive_looks: tuple[str, ...] = DRIVE_LOOKS) -> str:
    """Markdown: per net and training look, the distance to the first collision in each driving look
    (mean [95 % interval] over seeds, ends reached in all), and each driving look's mean as a share
    of the training look's own."""
    head = ["Q-net", "trained in", *(f"driven in {d}: m (ends)" for d in drive_looks),
            *(f"{d} / own" for d in drive_looks)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for net, label in NETS.items():
        for look in train_looks:
            means, cells = {}, []
            for drive in drive_looks:
                found = [s for seed in seeds
                         if (s := evaluation_summary(Path(out) / look / f"eval_{drive}" / f"{net}_s{seed}"))]
                values = [s["distance_to_collision_mean"] for s in found]
                means[drive] = float(np.mean(values)) if values else None
                ends = sum(int(s["successes"]) for s in found)
                cells.append(f"{mean_interval(values, '.2f', len(seeds))} ({ends})" if values else "–")
            own = means.get(look)
            shares = [f"{means[d] / own:.0%}" if own and means[d] is not None else "–" for d in drive_looks]
            lines.append("| " + " | ".join([label, look, *cells, *shares]) + " |")
    return "\n".join(lines)


def _looks(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(","))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    fig = actions.add_parser("figure", help="the same pose in every look: DOCS/looks.png")
    fig.add_argument("docs", nargs="?", type=Path, default=Path("docs"), help="folder of looks.png")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("out", type=Path, help="the experiment's folder (created; resumed)")
    common.add_argument("--runs", type=int, default=500, help="training runs of every Q-net (default: 500)")
    common.add_argument("--seeds", default="0-2", help="training seeds (default: 0-2)")
    common.add_argument("--train-looks", default=",".join(TRAIN_LOOKS), help="looks the nets learn in")
    common.add_argument("--drive-looks", default=",".join(DRIVE_LOOKS), help="looks every net drives in")
    go = actions.add_parser("run", parents=[common], help="sweeps, camera labels, evaluations (resumed)")
    go.add_argument("--preset", default="hard", help="the sweep preset the training follows (default: hard)")
    go.add_argument("--canyons", default="hard/eval", help="the canyons of the table (default: hard/eval)")
    go.add_argument("--choose", default=CHOOSE, help=f"the canyons of every choice (default: {CHOOSE})")
    go.add_argument("--method", default="monodepth", help="the camera labeller (default: monodepth)")
    go.add_argument("--time-limit", type=float, default=None, help="seconds per evaluation run")
    go.add_argument("--labeller-set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a LabellerConfig setting, as camera_labels takes it; repeatable")
    go.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a training setting of every Q-net, one value; repeatable")
    go.add_argument("--workers", type=int, default=2, help="processes per evaluation (default: 2)")
    go.add_argument("--device", default="auto", help="torch device (default: auto)")
    go.add_argument("--no-progress", action="store_true", help="no progress bars")
    actions.add_parser("table", parents=[common], help="the Markdown table of what OUT holds")
    args = parser.parse_args(argv)

    def work() -> int:
        if args.action == "figure":
            figure(args.docs / "looks.png")
            print(f"wrote {args.docs / 'looks.png'}")
            return 0
        seeds = parse_ints(args.seeds, "--seeds")
        train_looks, drive_looks = _looks(args.train_looks), _looks(args.drive_looks)
        if args.action == "table":
            print(table(args.out, args.runs, seeds, train_looks, drive_looks))
            return 0
        return run(args.out, preset=args.preset, runs=args.runs, seeds=seeds, canyons=args.canyons,
                   choose=args.choose, train_looks=train_looks, drive_looks=drive_looks, method=args.method,
                   time_limit_s=args.time_limit,
                   labeller_settings=camera_labels.parse_settings(args.labeller_set, "--labeller-set"),
                   training=camera_labels.parse_settings(args.set, "--set"), workers=args.workers,
                   device=args.device, progress=not args.no_progress)

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
