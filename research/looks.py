"""Looks (docs/design.md#looks): the same pose in every look, and which value signal transfers across
looks (issue #45 item 3; docs/research/looks.md).

    python -m research.looks figure [DOCS]          # DOCS/looks.png (default docs/)
    python -m research.looks run OUT [--runs 500] [--seeds 0-2] [--canyons hard/eval]
    python -m research.looks table OUT [--runs 500] [--seeds 0-2]
    python -m research.looks report OUT [--runs 500] [--seeds 0-2]   # OUT/report.md, .html

`run` (resumed: every step is skipped when its output is complete), per training look L (default
colours, textured), hard canyons:

    OUT/<L>/sweep/             `depthq sweep --preset hard --look L --runs N --sizes N --seeds S
                               --canyons <choose>`: the data in look L, the Depth-Q-Nets (LiDAR labels)
                               and Coll-Q-Nets, evaluated in look L in the choice canyons
    OUT/<L>/camera/            `python -m research.camera_labels run` on it (--method
                               monodepth): the labeller, its labels' error, the camera-label Depth-Q-Nets
    OUT/<L>/eval_<D>/<net>_s<S>/  every net (depth, camera, coll) driven in look D (default colours,
                               textured, heldout) in `--canyons`

then, per driving look D:

    OUT/val_<D>/data/          `--val-runs` validation runs in look D (val canyons, seed VAL_SEED)
    OUT/val_<D>/<method>_<L>.json  the labeller trained in L measured there against the LiDAR's bins
    OUT/val_<D>/predictions_<L>_<net>_s<S>.json  each net's offline metric there (its loss on those runs)

`table` prints, per net and training look, the distance to the first collision (mean [95 %
interval] over seeds) in each driving look, and each look's share of the training look's; then per
training look its labeller's nearest-bin error in each driving look. `report` writes both, each net's
offline metric in each driving look, the held-out look's cost to the colour-trained nets beside what
textured training gives back (paired by seed), how far each net's training carries to new runs of its
look (validation loss by epoch), the issue's two "done when" answers and the same pose in every look
(OUT/looks.png) into OUT/report.md and OUT/report.html.
"""

from __future__ import annotations

import argparse
import html
import io
import json
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from PIL import Image, ImageDraw

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from depthq.checkpoint import CONFIG, METRICS, chosen_weights, read_config, read_metrics, weights_stem
from depthq.checksum import read_checked_json, write_checked_json
from depthq.configio import atomic_write_bytes, field_paths, read_json, to_dict, write_json
from depthq.data.manifest import Dataset
from depthq.data.recorder import CollectConfig, collect, collection_complete
from depthq.data.rerender import rerender
from depthq.data.stats import error_cell, label_errors
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import EvalConfig, evaluate, evaluation_done, parse_canyon_set
from depthq.evaluate.oracle import Oracle
from depthq.evaluate.probe import agreement_file, measure_agreement
from depthq.flags import build_config, config_flags, get_path
from depthq.labellers.labeller import CONFIG as LABELLER_CONFIG
from depthq.labellers.labeller import LabellerConfig, check_applicable, load_labeller
from depthq.lock import exclusive
from depthq.pipeline.layout import model_name
from depthq.pipeline.presets import get_preset
from depthq.pipeline.runner import run_sweep
from depthq.pipeline.sweep import Model, Settings, Sweep, parse_ints, retarget, widened
from depthq.progress import Bar
from depthq.report import html as page
from depthq.report.build import build_report
from depthq.report.cells import evaluation_summary, mean_interval
from depthq.report.paired import Summaries, by_seed
from depthq.report.tables import markdown
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.look import BROAD, COLOURS, HELDOUT, LOOKS, TEXTURED, check_look
from depthq.sim.world import WorldConfig, world_for
from depthq.train.config import TrainConfig
from depthq.train.dead_outputs import count_dead_outputs
from depthq.train.offline_metric import offline_metric
from research import camera_labels
from research.timing import timed

PROG = "python -m research.looks"
CANYON = "hard/val:1000"  # the figure's: a val canyon (the docs show no test canyon)
# The figure's broad-look row: the same drive in four val canyons, the first the figure's.
BROAD_CANYONS = tuple(f"hard/val:{k}" for k in range(1000, 1004))
POSE_STEPS = 8  # straight ahead for this many decisions, then one turning step (blur in the textured looks)
TRAIN_LOOKS = (COLOURS, TEXTURED)
DRIVE_LOOKS = (COLOURS, TEXTURED, HELDOUT)
# A driving look of the experiment's own: a folder of images it generates (OUT/generated_look), drawn by
# a generator no bank or look uses (random translucent polygons on a gradient), so no net saw it.
GENERATED = "generated"
GENERATED_IMAGES, GENERATED_SEED = 24, 4242
RERENDER_SEED = 1  # the draw of every re-rendered look (`depthq dataset rerender --seed`)


@dataclass(frozen=True)
class Recipe:
    """How a training look's nets learn (issue #57): the runs collected in `look`, each rendered again
    in every look of `rerender` (`depthq dataset rerender`: the same poses, LiDAR and actions, new
    frames), trained with `training` and labelled by a labeller with `labeller`, each over the pinned
    settings. A look's name alone is today's recipe: that look, nothing more."""

    look: str
    rerender: tuple[str, ...] = ()
    training: tuple[tuple[str, Any], ...] = ()
    labeller: tuple[tuple[str, Any], ...] = ()


_MANY = (COLOURS, TEXTURED)  # the looks a broad collection is rendered again in
_TUNED = (("tune_stages", 1),)
_LIVE = (*_TUNED, ("depth.bin_gradient", "straight_through"))  # and no dead output
# The recipes of issue #57, each the one before it and one more item: chosen among on `val` (`diagnose`).
# The labeller's brightness compensation is not a rung: on validation frames it read depth worse
# (docs/research/camera_labels.md#brightness), so every recipe's labeller keeps the default.
RECIPES: dict[str, Recipe] = {
    "broad": Recipe(BROAD),
    "broad+looks": Recipe(BROAD, _MANY),
    "broad+looks+tuned": Recipe(BROAD, _MANY, _TUNED),
    "broad+looks+tuned+st": Recipe(BROAD, _MANY, _LIVE),
}


def recipe(name: str) -> Recipe:
    """The recipe `name` names: one of RECIPES, or a look's name (that look alone)."""
    if name in RECIPES:
        return RECIPES[name]
    if name in LOOKS:
        return Recipe(name)
    raise ConfigError(f"unknown recipe {name!r}: a look ({', '.join(LOOKS)}) or one of {', '.join(RECIPES)}")


def generated_look(out: Path) -> Path:
    """OUT/generated_look: GENERATED_IMAGES images of random translucent polygons on a colour gradient,
    made once (the same bytes on every machine: numpy's generator and Pillow's drawing)."""
    folder = Path(out) / "generated_look"
    names = [f"generated_{k:02d}.png" for k in range(GENERATED_IMAGES)]
    if all((folder / name).is_file() for name in names):
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(GENERATED_SEED)
    for name in names:
        size = 256
        ramp = np.linspace(0.0, 1.0, size)[:, None, None]
        top, bottom = rng.uniform(0, 255, 3), rng.uniform(0, 255, 3)
        base = (top * (1 - ramp) + bottom * ramp) * np.ones((1, size, 1))
        image = Image.fromarray(base.astype(np.uint8)).convert("RGBA")
        layer = Image.new("RGBA", image.size)
        draw = ImageDraw.Draw(layer)
        for _ in range(int(rng.integers(20, 60))):
            corners = int(rng.integers(3, 6))
            centre, radius = rng.uniform(0, size, 2), rng.uniform(8, 80)
            angles = np.sort(rng.uniform(0, 2 * np.pi, corners))
            points = [(float(centre[0] + radius * np.cos(a)), float(centre[1] + radius * np.sin(a)))
                      for a in angles]
            colour = (*(int(c) for c in rng.integers(0, 256, 3)), int(rng.integers(90, 230)))
            draw.polygon(points, fill=colour)
        image = Image.alpha_composite(image, layer).convert("RGB")
        buffer = io.BytesIO()
        image.save(buffer, format="PNG")
        atomic_write_bytes(folder / name, buffer.getvalue())
    return folder


def look_of(out: Path, key: str) -> str:
    """The look a driving look's key names: GENERATED is OUT's generated folder, any other key a look."""
    if key == GENERATED:
        return str(generated_look(out))
    check_look(key)
    return key


def check_drive_looks(keys: tuple[str, ...]) -> None:
    """A ConfigError naming the first driving look that is neither a look nor GENERATED."""
    for key in keys:
        if key != GENERATED:
            check_look(key)


def prepare_data(out: Path, name: str, sweep: Sweep, workers: int, progress: bool) -> None:
    """A recipe's dataset before its sweep: with re-rendered looks, the sweep's collection (as the sweep
    would make it) and its runs rendered again in each; the first recipe of the same collection and
    looks makes it, the others link to it (resumed)."""
    wanted = recipe(name)
    if not wanted.rerender:
        return
    data = out / name / "sweep" / "data"
    twin = next(other for other in RECIPES if (recipe(other).look, recipe(other).rerender) ==
                (wanted.look, wanted.rerender))
    if twin != name:
        data.parent.mkdir(parents=True, exist_ok=True)
        if not data.exists():
            data.symlink_to(out / twin / "sweep" / "data")
        prepare_data(out, twin, sweep, workers, progress)
        return
    if not collection_complete(data, sweep.collect):
        print(f"collect in the {wanted.look} look → {data}", flush=True)
        collect(data, sweep.collect, workers=workers, progress=progress)
    print(f"rerender {data} in {', '.join(wanted.rerender)}", flush=True)
    rerender(data, wanted.rerender, seed=RERENDER_SEED, workers=workers, progress=progress)
def share_labeller(out: Path, name: str, method: str) -> None:
    """A recipe's labeller and labelled data linked to an earlier recipe's whose data and labeller
    settings are the same and whose labeller has finished: the same labeller, learnt once."""
    made = recipe(name)
    for other in RECIPES:
        if other == name:
            return
        theirs = recipe(other)
        source = out / other / "camera" / method
        if ((theirs.look, theirs.rerender, theirs.labeller) == (made.look, made.rerender, made.labeller)
                and (source / "labeller" / LABELLER_CONFIG).is_file()):
            folder = out / name / "camera" / method
            folder.mkdir(parents=True, exist_ok=True)
            for part in ("labeller", "data"):
                if not (folder / part).exists():
                    (folder / part).symlink_to(source / part)
            return


CHOOSE = "hard/val:1000-1019"  # where the sweep and the camera-label experiment make their choices
NETS = {"depth": "Depth-Q-Net, LiDAR labels", "camera": "Depth-Q-Net, camera labels", "coll": "Coll-Q-Net"}
# Nets driven again with other weights than their own choice: Coll-Q-Net with its last epoch's, which
# drove 2-7 times as far as its best epoch in every look of the broad+looks recipe on `val`
# (docs/research/looks.md#coll-weights), so that the table gives it its best chance.
# key → (net, weights, label).
REWEIGHED = {"coll_final": ("coll", "final", "Coll-Q-Net, last epoch's weights")}
DRIVEN = {**NETS, **{key: label for key, (_, _, label) in REWEIGHED.items()}}  # the distance table's rows
# The labellers are measured in every driving look on OUT/val_<look>/data: VAL_RUNS validation runs (in
# the `val` canyons, as a dataset's val split) collected with VAL_SEED, a seed no sweep collects with
# (sweeps draw their OU and sensor noise from seed 0), so no frame is one a labeller or net learnt on.
VAL_RUNS, VAL_SEED = 20, 1000
# The issue's "done when" (#45): the camera-label Depth-Q-Net trained in the textured look keeps this
# share of its textured distance in the held-out look, and drives there at least as far as Coll-Q-Net.
DONE_SHARE = 0.9
NOT_MEASURED = "not yet measured"

# Every setting the experiment's nets train with (TrainConfig field paths; "lr" the effective rate),
# as the `hard` preset and the defaults of commit 0ab0c20 gave them, where the run behind
# docs/research/looks.md started. `run` gives every training the pinned values today's preset and
# defaults no longer hold (none on that commit), so the documented command trains the same nets on a
# later commit. The camera-label Depth-Q-Net trains as the LiDAR one (`camera_labels.camera_config`),
# on camera labels.
_PINNED: dict[str, Any] = {
    "epochs": 40, "train_batches": 100, "val_batches": 10, "batch_size": 64, "lr": 0.1, "rho": 0.95,
    "eps": 1e-08, "weight_decay": 4e-05, "trunk": "efficientnet_lite0_columns", "tune_stages": 0,
    "dropout": 0.0, "action_scale": 10.0, "input_size": 128, "feature_projection": 0, "hidden": 4096,
    "mirror": False, "labels": "lidar", "samples.horizon": 5, "samples.min_frames": 20,
    "samples.every_run_end": True, "samples.action_clip": 1.0, "samples.action_lag": 0, "snapshots": [],
    "precision": "fp32",
}
PINNED_TRAINING: dict[str, dict[str, Any]] = {  # every field, and each network's own settings
    "depth": {**_PINNED, "depth.depth_loss": "original", "depth.lookahead": 1,
              "depth.lookahead_discount": 1.0, "depth.head_form": "depth_first", "depth.output_bias": 0.0,
              "depth.bin_gradient": "relu", "depth.bootstrap": 0.0, "weights": "average", "average": 0.25},
    "coll": {**_PINNED, "weights": "best", "average": 0.0},
}
# The monodepth labeller's settings (LabellerConfig, besides its data and method), pinned as above.
PINNED_LABELLER: dict[str, Any] = {
    "trunk": "efficientnet_lite0_columns", "input_size": 128, "hidden": 4096, "scale": 4, "width": 16,
    "context": True, "lookahead": 12, "nearest": 0.3, "memory_s": 2.0, "pool_frames": 6, "pool_runs": 300,
    "min_depth": 0.1, "max_depth": 10.0, "smoothness": 0.001, "steps": 1500, "batch_size": 8, "lr": 0.001,
    "seed": 0, "brightness": "none", "pool": "collected",
}
PINNED_PRESET, PINNED_METHOD = "hard", "monodepth"  # another preset or labeller trains as it does today


_GONE = object()


def _flat(config: Any) -> dict[str, Any]:
    """A config's fields by path ('samples.horizon', 'depth.lookahead'), JSON values; a training's "lr" its
    effective rate."""
    if isinstance(config, TrainConfig):  # its network's own settings by their paths ('depth.lookahead')
        paths = {f.path: get_path(config, f.path) for f in config_flags(TrainConfig, config)}
        return {**json.loads(json.dumps(paths)), "lr": config.learning_rate}
    return field_paths(json.loads(json.dumps(asdict(config))))


def _restoring(pins: dict[str, dict[str, Any]], built: dict[str, dict[str, Any]],
               given: set[str]) -> tuple[tuple[str, Any], ...]:
    """The settings (field path, value) that bring each built config back to its pin, but for the
    fields `given` on the command line; every config takes them all (a sweep's settings are every
    net's, a network's own settings its alone), so a setting must suit each pin that has it."""
    needed: dict[str, Any] = {}
    for name, pin in pins.items():
        for key, value in pin.items():
            if key not in given and built[name].get(key, _GONE) != value:  # gone: build_config names it
                needed[key] = value
    for key, value in needed.items():
        if clash := [name for name, pin in pins.items() if pin.get(key, value) != value]:
            raise ConfigError(f"the defaults moved away from the looks experiment's pinned {key} differently "
                              f"for {', '.join(clash)}: pin that setting per network in "
                              f"research.looks")
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


def figure(path: Path, canyon: str = CANYON, broad: tuple[str, ...] = BROAD_CANYONS) -> None:
    """The looks' frames at the same pose in a row, then the broad look's in the canyons `broad` (the
    first is `canyon`), each labelled, as a PNG."""
    def tile(image: np.ndarray, label: str) -> np.ndarray:
        picture = Image.fromarray(image)
        ImageDraw.Draw(picture).text((8, 6), label, fill=(255, 255, 255))
        return np.asarray(picture)

    others = tuple(look for look in LOOKS if look != BROAD)
    looks = [tile(image, look) for look, image in frames(canyon, others).items()]
    wide = [tile(frames(c, (BROAD,))[BROAD], f"{BROAD}, {c}") for c in broad]
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate([np.concatenate(looks, 1), np.concatenate(wide, 1)], 0)).save(path)


def checkpoints(out: Path, look: str, runs: int, seed: int, method: str) -> dict[str, Path]:
    """The nets trained in `look`: the sweep's Depth-Q-Net and Coll-Q-Net, the camera-label Depth-Q-Net."""
    name = model_name("depth", runs, seed)
    return {"depth": out / look / "sweep" / "models" / name,
            "camera": out / look / "camera" / method / "models" / name,
            "coll": out / look / "sweep" / "models" / model_name("coll", runs, seed)}


def val_collect(preset: str, look: str, val_runs: int = VAL_RUNS) -> CollectConfig:
    """The validation set of a driving look: the preset's collection in the hard family and `look`
    (the training data's robot, camera and exploration), `val_runs` val runs seeded by VAL_SEED (and
    the one training run a dataset needs, never used)."""
    sweep = retarget(get_preset(preset), family="hard", look=look)
    return replace(sweep.collect, runs=1, val_runs=val_runs, seed=VAL_SEED)


def labeller_errors(labellers: list[Path], data: Path, split: str = "val", progress: bool = True
                    ) -> list[dict[str, Any]]:
    """The labellers in folders `labellers` measured on a dataset's `split`, each run decoded once for
    all of them (its frames labelled in memory, nothing written): per labeller,
    `depthq.data.stats.label_errors` against the LiDAR's bins, and what was measured."""
    loaded, dataset = [load_labeller(folder) for folder in labellers], Dataset.open(data)
    for labeller in loaded:
        check_applicable(labeller, dataset)
    entries = dataset.entries(split)
    if not entries:
        raise ConfigError(f"{data} has no {split} runs to measure the labellers "
                          f"{', '.join(map(str, labellers))} on")
    lidar: list[np.ndarray] = []
    camera: list[list[np.ndarray]] = [[] for _ in loaded]
    bar = Bar(entries, desc=f"labellers on {Path(data).parent.name}", unit="run", disable=not progress)
    for entry in bar:
        one = dataset.read_run(entry, images=True)
        lidar.append(one.bins)
        for labels, labeller in zip(camera, loaded, strict=True):
            labels.append(labeller.estimate(one))
    bins, fingerprint = np.concatenate(lidar), dataset.fingerprint()
    return [{"labeller": str(folder), "name": labeller.record["name"], "fingerprint": labeller.fingerprint,
             "data": str(data), "data_fingerprint": fingerprint, "split": split,
             **label_errors(bins, np.concatenate(labels), len(entries))}
            for folder, labeller, labels in zip(labellers, loaded, camera, strict=True)]


def error_path(out: Path, look: str, drive: str, method: str) -> Path:
    """Where the error of the `method` labeller trained in `look`, measured in `drive`, is kept."""
    return Path(out) / f"val_{drive}" / f"{method}_{look}.json"


def measure_labellers(out: Path, preset: str, train_looks: tuple[str, ...], drive_looks: tuple[str, ...],
                      method: str, val_runs: int = VAL_RUNS, workers: int = 2, progress: bool = True) -> None:
    """Each driving look's validation set collected into OUT/val_<look>/data, and each training look's
    labeller measured on it, its runs decoded once for them all (resumed: a finished collection or
    measurement is kept)."""
    for drive in drive_looks:
        data, config = Path(out) / f"val_{drive}" / "data", val_collect(preset, look_of(out, drive), val_runs)
        if not collection_complete(data, config):
            print(f"validation runs in the {drive} look → {data}", flush=True)
            collect(data, config, workers=workers, progress=progress)
        todo = {}  # labeller → where its error is kept, of those not measured yet
        for look in train_looks:
            labeller = Path(out) / look / "camera" / method / "labeller"
            path = error_path(out, look, drive, method)
            if not path.is_file() and (labeller / LABELLER_CONFIG).is_file():
                print(f"labeller {labeller} in the {drive} look → {path}", flush=True)
                todo[labeller] = path
        if todo:
            for path, record in zip(todo.values(), labeller_errors(list(todo), data, progress=progress),
                                    strict=True):
                write_json(path, record)


# What to do when a checked record of this experiment (a net's predictions or agreement) is corrupted.
FIX = f"remove it and rerun `{PROG} run` (predictions) or `{PROG} diagnose` (agreement) to measure it again"


def _drive(checkpoint: Path, folder: Path, config: EvalConfig, workers: int, progress: bool,
           device: str) -> None:
    """`checkpoint` evaluated into `folder` unless a finished evaluation of it as it acts now is there."""
    if not evaluation_done(folder):
        print(f"evaluate {checkpoint} in the {config.look} look → {folder}", flush=True)
        evaluate(str(checkpoint), folder, config, workers=workers, progress=progress, device=device,
                 video=False)


def prediction_path(out: Path, look: str, drive: str, net: str, seed: int) -> Path:
    """Where the offline metric of `net` (seed `seed`) trained in `look`, on `drive`'s validation runs,
    is kept."""
    return Path(out) / f"val_{drive}" / f"predictions_{look}_{net}_s{seed}.json"


def measure_predictions(out: Path, runs: int, seeds: tuple[int, ...], train_looks: tuple[str, ...],
                        drive_looks: tuple[str, ...], method: str) -> None:
    """Every net's offline metric (its training loss against the LiDAR's bins or the bump,
    `depthq.train.offline_metric`) on each driving look's validation runs, OUT/val_<look>/data: how
    well it predicts in a look, apart from how it drives there (resumed: a record made with the
    weights its checkpoint acts with now is kept)."""
    for drive in drive_looks:
        data, dataset = Path(out) / f"val_{drive}" / "data", None
        for look in train_looks:
            for seed in seeds:
                for net, checkpoint in checkpoints(out, look, runs, seed, method).items():
                    path = prediction_path(out, look, drive, net, seed)
                    if not (checkpoint / CONFIG).is_file():
                        continue
                    stem = weights_stem(chosen_weights(read_config(checkpoint), None, checkpoint))
                    if path.is_file() and read_checked_json(path, FIX)["weights"] == stem:
                        continue
                    print(f"offline metric of {checkpoint} in the {drive} look → {path}", flush=True)
                    dataset = dataset or Dataset.open(data)
                    record = offline_metric(checkpoint, dataset)
                    write_checked_json(path, {**record, "checkpoint": str(checkpoint), "data": str(data),
                                              "data_fingerprint": dataset.fingerprint()})


def run(out: Path, *, preset: str = "hard", runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
        canyons: str = "hard/eval", choose: str = CHOOSE, train_looks: tuple[str, ...] = TRAIN_LOOKS,
        drive_looks: tuple[str, ...] = DRIVE_LOOKS, method: str = "monodepth",
        time_limit_s: float | None = None,
        labeller_settings: tuple[tuple[str, Any], ...] = (), training: tuple[tuple[str, Any], ...] = (),
        val_runs: int = VAL_RUNS, workers: int = 2, device: str = "auto", progress: bool = True,
        train_only: bool = False) -> int:
    """The experiment into OUT (resumed): per recipe (`train_looks`: recipes' or looks' names) its
    sweep and camera labels, trained with their choices on `choose`; unless `train_only`, every net
    driven in each driving look in `canyons`, the labellers and predictions measured; then its tables."""
    out = Path(out).resolve()
    recipes = {name: recipe(name) for name in train_looks}  # checked up front, as the rest
    check_drive_looks(drive_looks)
    driving = EvalConfig(canyons=parse_canyon_set(canyons), time_limit_s=time_limit_s)
    if val_runs < 1:
        raise ConfigError(f"--val-runs must be >= 1, got {val_runs}")
    for name, made in recipes.items():
        sweep = retarget(get_preset(preset), family="hard", canyons=choose, look=made.look)
        if time_limit_s is not None:
            limit = {**dict(sweep.evaluate), "time_limit_s": time_limit_s}
            sweep = replace(sweep, evaluate=tuple(limit.items()))
        sweep = widened(sweep, runs, subsets=(runs,), seeds=seeds, name=f"{preset}, recipe {name}")
        pinned = pinned_training(sweep, runs, seeds[0], (*made.training, *training), preset)
        sweep = replace(sweep, train=tuple({**dict(sweep.train), **dict(pinned)}.items()))
        prepared = not made.rerender or (out / name / "sweep" / "stages.json").is_file()  # its sweep began
        with timed(out / name, "collect and rerender", done=prepared):
            prepare_data(out, name, sweep, workers, progress)
        print(f"sweep of recipe {name} → {out / name / 'sweep'}", flush=True)
        run_sweep(sweep, out / name / "sweep", progress=progress, device=device, finish=build_report)
        share_labeller(out, name, method)
        camera_labels.run(out / name / "sweep", out / name / "camera", method, runs=runs, seeds=seeds,
                          canyons=choose, time_limit_s=time_limit_s, look=made.look,
                          labeller_settings=pinned_labeller(method, (*made.labeller, *labeller_settings)),
                          training=tuple((k, v) for k, v in pinned if k != "labels"),  # camera's own
                          workers=workers,
                          device=device, progress=progress)
        if train_only:
            continue
        for drive in drive_looks:
            config = replace(driving, look=look_of(out, drive))
            for seed in seeds:
                trained = checkpoints(out, name, runs, seed, method)
                for net, checkpoint in trained.items():
                    if (checkpoint / CONFIG).is_file():
                        _drive(checkpoint, out / name / f"eval_{drive}" / f"{net}_s{seed}", config,
                               workers, progress, device)
                for key, (net, weights, _) in REWEIGHED.items():
                    if (trained[net] / CONFIG).is_file():
                        _drive(trained[net], out / name / f"eval_{drive}" / f"{key}_s{seed}",
                               replace(config, weights=weights), workers, progress, device)
    if train_only:
        print(f"trained: {', '.join(recipes)}; choose among them with `{PROG} diagnose` on `val`")
        return 0
    measure_labellers(out, preset, train_looks, drive_looks, method, val_runs, workers, progress)
    measure_predictions(out, runs, seeds, train_looks, drive_looks, method)
    print(table(out, runs, seeds, train_looks, drive_looks, method))
    return 0


DIAGNOSE_NETS = ("depth", "camera")  # the nets whose scores the depth oracle's compare with


def diagnosis_folder(out: Path, look: str, drive: str) -> Path:
    """Where `diagnose` drives the nets trained in `look` in the choice canyons in `drive`, and keeps
    their agreement."""
    return Path(out) / look / f"diagnose_{drive}"


def diagnose(out: Path, *, runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
             train_looks: tuple[str, ...] = (TEXTURED,), drive_looks: tuple[str, ...] = (TEXTURED, HELDOUT),
             nets: tuple[str, ...] = DIAGNOSE_NETS, choose: str = CHOOSE, method: str = PINNED_METHOD,
             time_limit_s: float | None = None, workers: int = 2, device: str = "auto",
             progress: bool = True) -> int:
    """Why a net drives one look less far than another, on the choice canyons (never the table's): each
    net trained in a training look driven in each driving look, then along its own runs the depth
    oracle's action at every pose and the net's prediction from the frame re-rendered there
    (`depthq.evaluate.oracle.agreement`): how often it took the best action, and how far its scores
    are from the true ones, on the states it reached (resumed)."""
    out = Path(out).resolve()
    for name in train_looks:
        recipe(name)
    check_drive_looks(drive_looks)
    unknown = sorted(set(nets) - set(NETS))
    if unknown:
        raise ConfigError(f"--nets {','.join(unknown)}: not a net of this experiment ({', '.join(NETS)})")
    driving = EvalConfig(canyons=parse_canyon_set(choose), time_limit_s=time_limit_s)
    oracle = Oracle()
    for look in train_looks:
        for drive in drive_looks:
            where = diagnosis_folder(out, look, drive)
            for seed in seeds:
                for net, checkpoint in checkpoints(out, look, runs, seed, method).items():
                    folder = where / f"{net}_s{seed}"
                    if net not in nets or not (checkpoint / CONFIG).is_file():
                        continue
                    config = replace(driving, look=look_of(out, drive))
                    driven = out / look / f"eval_{drive}" / folder.name  # `run` in the same canyons
                    if evaluation_done(folder) or not _driven_as(driven, config):
                        _drive(checkpoint, folder, config, workers, progress, device)
                        driven = folder
                    path = agreement_file(where, folder.name, oracle, ".json")
                    weights = read_json(driven / "summary.json")["policy"]["weights"]
                    if path.is_file() and read_checked_json(path, FIX)["weights"] == weights:
                        continue
                    print(f"agreement of {driven} → {path}", flush=True)
                    summary = measure_agreement(driven, oracle, where, predictions=True)
                    write_checked_json(path, {**summary, "weights": weights})
    print(markdown(diagnosis_rows(out, seeds, train_looks, drive_looks, nets)))
    return 0


def _driven_as(folder: Path, config: EvalConfig) -> bool:
    """Whether `folder` holds a finished evaluation driven in `config`'s canyons, look and time limit
    (`run` drove it where `diagnose` would: its runs are measured instead of driving them again)."""
    if not evaluation_done(folder):
        return False
    held, wanted = read_json(folder / "summary.json")["config"], to_dict(config)
    keys = ("canyons", "look") if config.time_limit_s is None else ("canyons", "look", "time_limit_s")
    return all(held.get(key) == wanted.get(key) for key in keys)  # none (left out): the family's


DIAGNOSIS = {"distance_to_collision_mean": ("m to first collision", ".2f"),
             "agreement_decisive": ("took the best action, decisive steps", ".1%"),
             "agreement_before_collision": ("took the best action, last 2 s before a collision", ".1%"),
             "score_error": ("score error: m", ".3f"), "true_spread": ("true spread: m", ".3f"),
             "predicted_spread": ("predicted spread: m", ".3f"),
             "same_decision_new_noise": ("same decision, frame rendered again", ".1%")}


def _agreement_records(out: Path, net: str, look: str, drive: str, seeds: tuple[int, ...]
                       ) -> list[dict[str, Any]]:
    """`diagnose`'s agreement summaries of `net` trained in `look`, driven in `drive`, per seed measured."""
    where = diagnosis_folder(out, look, drive)
    return [read_checked_json(p, FIX) for seed in seeds
            if (p := agreement_file(where, f"{net}_s{seed}", Oracle(), ".json")).is_file()]


def diagnosis_rows(out: Path, seeds: tuple[int, ...] = (0, 1, 2), train_looks: tuple[str, ...] = (TEXTURED,),
                   drive_looks: tuple[str, ...] = (TEXTURED, HELDOUT), nets: tuple[str, ...] = DIAGNOSE_NETS
                   ) -> list[dict[str, str]]:
    """Per net, training look and driving look, `diagnose`'s agreement summaries (mean [95 % interval]
    over the seeds measured): how far it drove the choice canyons, how often it took the depth
    oracle's best action, and its scores' error and spread against the truth along its own runs."""
    rows = []
    for net in nets:
        for look in train_looks:
            for drive in drive_looks:
                found = _agreement_records(out, net, look, drive, seeds)
                row = {"Q-net": NETS[net], "trained in": look, "driven in": drive, "seeds": str(len(found))}
                for key, (title, spec) in DIAGNOSIS.items():
                    values = [float(f[key]) for f in found if f.get(key) is not None]
                    row[title] = mean_interval(values, spec, len(seeds)) if values else "–"
                rows.append(row)
    return rows


def _distances(out: Path, net: str, look: str, drive: str, seeds: tuple[int, ...]) -> Summaries:
    """seed → evaluation summary of `net` trained in `look`, driven in `drive`, where it is written."""
    folder = Path(out) / look / f"eval_{drive}"
    found = {seed: evaluation_summary(folder / f"{net}_s{seed}") for seed in seeds}
    return {seed: summary for seed, summary in found.items() if summary is not None}


def _d2c(found: Summaries) -> list[float]:
    return [float(s["distance_to_collision_mean"]) for s in found.values()]


def table_rows(out: Path, runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
               train_looks: tuple[str, ...] = TRAIN_LOOKS, drive_looks: tuple[str, ...] = DRIVE_LOOKS
               ) -> list[dict[str, str]]:
    """Per net and training look, the distance to the first collision in each driving look (mean
    [95 % interval] over seeds, ends reached in all), and each driving look's mean as a share of the
    training look's own."""
    rows = []
    for net, label in DRIVEN.items():
        for look in train_looks:
            means, row = {}, {"Q-net": label, "trained in": look}
            for drive in drive_looks:
                found = _distances(out, net, look, drive, seeds)
                values = _d2c(found)
                means[drive] = float(np.mean(values)) if values else None
                ends = sum(int(s["successes"]) for s in found.values())
                row[f"driven in {drive}: m (ends)"] = (f"{mean_interval(values, '.2f', len(seeds))} ({ends})"
                                                       if values else "–")
            own = means.get(look)
            for drive in drive_looks:
                share = means[drive] / own if own and means[drive] is not None else None
                row[f"{drive} / own"] = "–" if share is None else f"{share:.0%}"
            rows.append(row)
    return rows


def table(out: Path, runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
          train_looks: tuple[str, ...] = TRAIN_LOOKS, drive_looks: tuple[str, ...] = DRIVE_LOOKS,
          method: str = PINNED_METHOD) -> str:
    """Markdown: the nets' table (`table_rows`), then the labellers' (`labeller_rows`)."""
    return (markdown(table_rows(out, runs, seeds, train_looks, drive_looks)) + "\n"
            + markdown(labeller_rows(out, train_looks, drive_looks, method)))


def labeller_rows(out: Path, train_looks: tuple[str, ...] = TRAIN_LOOKS,
                  drive_looks: tuple[str, ...] = DRIVE_LOOKS, method: str = PINNED_METHOD
                  ) -> list[dict[str, str]]:
    """Per training look, its labeller's nearest-bin error against the LiDAR (median [mean] m, as
    the camera-labels experiment reports it): on the training runs it labelled, then on each driving
    look's validation runs (OUT/val_<look>)."""
    rows = []
    for look in train_looks:
        stats = camera_labels.read_stats(Path(out) / look / "camera" / method)
        row = {"labeller": f"{method}, trained in {look}",
               "its training runs: nearest bin, m": camera_labels.error_cells(stats)[0]}
        for drive in drive_looks:
            path = error_path(out, look, drive, method)
            record = read_json(path) if path.is_file() else None
            row[f"{drive} val runs: nearest bin, m"] = (
                f"{error_cell(record['nearest'])} ({record['frames']} frames)"
                if record else "–")
        rows.append(row)
    return rows


LEARNING_COLUMNS = ("val loss, epoch 1", "val loss, best (epoch per seed)", "val loss, last epoch",
                    "best / epoch 1", "train loss, last epoch")


def learning_rows(out: Path, runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
                  train_looks: tuple[str, ...] = TRAIN_LOOKS, method: str = PINNED_METHOD
                  ) -> list[dict[str, str]]:
    """Per net and training look, how far training carries to the look's validation runs (mean over
    the seeds trained): the validation loss after the first epoch, at its best, at the last epoch, the
    best as a share of the first (near 100 %: nothing learnt after the first epoch carries to new
    runs), and the training loss at the last epoch. Each net's own loss (the camera-label net's against
    its labels), so compare looks within a row pair, not nets."""
    rows = []
    for net, label in NETS.items():
        for look in train_looks:
            logs = [m for seed in seeds
                    if ((folder := checkpoints(out, look, runs, seed, method)[net]) / METRICS).is_file()
                    and (m := read_metrics(folder))]
            row = {"Q-net": label, "trained in": look, "seeds": str(len(logs))}
            if not logs:
                rows.append({**row, **dict.fromkeys(LEARNING_COLUMNS, "–")})
                continue
            first = np.mean([m["val_loss"][0] for m in logs])
            best = np.mean([np.min(m["val_loss"]) for m in logs])
            best_epochs = ",".join(str(int(m["epoch"][np.argmin(m["val_loss"])])) for m in logs)
            cells = (f"{first:.3f}", f"{best:.3f} ({best_epochs})",
                     f"{np.mean([m['val_loss'][-1] for m in logs]):.3f}",
                     f"{best / first:.0%}" if first > 0 else "–",
                     f"{np.mean([m['train_loss'][-1] for m in logs]):.3f}")
            rows.append({**row, **dict(zip(LEARNING_COLUMNS, cells, strict=True))})
    return rows


def prediction_rows(out: Path, seeds: tuple[int, ...] = (0, 1, 2), train_looks: tuple[str, ...] = TRAIN_LOOKS,
                    drive_looks: tuple[str, ...] = DRIVE_LOOKS) -> list[dict[str, str]]:
    """Per net and training look, its offline metric on each driving look's validation runs (mean
    [95 % interval] over seeds; m of absolute difference for the Depth-Q-Nets, both scored against
    the LiDAR's bins, cross-entropy for Coll-Q-Net), and each look's as a multiple of its own look's."""
    rows = []
    for net, label in NETS.items():
        for look in train_looks:
            row, means, metric = {"Q-net": label, "trained in": look}, {}, "–"
            for drive in drive_looks:
                paths = [prediction_path(out, look, drive, net, seed) for seed in seeds]
                found = [read_checked_json(p, FIX) for p in paths if p.is_file()]
                values = [float(r["value"]) for r in found]
                metric = found[0]["metric"] if found else metric
                means[drive] = float(np.mean(values)) if values else None
                row[f"in {drive}"] = mean_interval(values, ".3f", len(seeds)) if values else "–"
            row["metric"] = metric
            for drive in drive_looks:
                ratio = means[drive] / means[look] if means.get(look) and means[drive] is not None else None
                row[f"{drive} / own"] = "–" if ratio is None else f"{ratio:.2f} ×"
            rows.append(row)
    return rows


def _paired(first: Summaries, second: Summaries) -> tuple[str, list[float]]:
    """second − first, m to the first collision paired by seed (`by_seed`): 'mean [95 % interval]
    (seeds)', and the differences."""
    pairs = by_seed(first, second)
    text = f"{mean_interval(pairs.diff, '+.2f')} (seeds {','.join(map(str, pairs.seeds))})"
    return (text if pairs.diff else "–"), pairs.diff


def transfer_rows(out: Path, seeds: tuple[int, ...] = (0, 1, 2), flat: str = COLOURS,
                  randomised: str = TEXTURED, heldout: str = HELDOUT) -> list[dict[str, str]]:
    """Per net, what the held-out look costs the nets trained in the `flat` look (held-out − own,
    paired by seed) beside what training in the `randomised` look gives back there (randomised −
    flat training, both driven in the held-out look, paired by seed); m to the first collision."""
    rows = []
    for net, label in NETS.items():
        own, away = _distances(out, net, flat, flat, seeds), _distances(out, net, flat, heldout, seeds)
        back = _distances(out, net, randomised, heldout, seeds)
        loss, _ = _paired(own, away)
        gain, _ = _paired(away, back)
        # the share over the seeds all three have, so the loss and the gain are of the same seeds
        common = set(own) & set(away) & set(back)
        lost = by_seed({s: own[s] for s in common}, away).diff
        gained = by_seed({s: away[s] for s in common}, back).diff
        share = (f"{np.mean(gained) / -np.mean(lost):.0%}" if lost and np.mean(lost) < 0 else "–")
        rows.append({
            "Q-net": label,
            f"trained {flat}, driven {flat}: m": mean_interval(_d2c(own), ".2f", len(seeds)),
            f"trained {flat}, driven {heldout}: m": mean_interval(_d2c(away), ".2f", len(seeds)),
            f"{heldout} − {flat}, paired: m": loss,
            f"trained {randomised}, driven {heldout}: m": mean_interval(_d2c(back), ".2f", len(seeds)),
            f"{randomised} − {flat} training in {heldout}, paired: m": gain,
            "share of the loss given back": share,
        })
    return rows


def answers(out: Path, seeds: tuple[int, ...] = (0, 1, 2), randomised: str = TEXTURED, heldout: str = HELDOUT
            ) -> list[str]:
    """The issue's two "done when" questions of the camera-label Depth-Q-Net trained in the
    `randomised` look, answered from OUT's evaluations ("not yet measured" where they are missing)."""
    camera = _distances(out, "camera", randomised, heldout, seeds)
    own = _distances(out, "camera", randomised, randomised, seeds)
    coll = _distances(out, "coll", randomised, heldout, seeds)
    where = f"{Path(out) / randomised}/eval_…/*_s<seed>"
    first = f"Does the camera-label Depth-Q-Net trained {randomised} drive the {heldout} look at ≥ " \
            f"{DONE_SHARE:.0%} of its distance in the {randomised} look? "
    both, here, there, _ = by_seed(own, camera)
    if both:
        share = np.mean(there) / np.mean(here)
        first += (f"**{'yes' if share >= DONE_SHARE else 'no'}**: {share:.0%} "
                  f"({mean_interval(there, '.2f')} m against {mean_interval(here, '.2f')} m, "
                  f"seeds {','.join(map(str, both))} of {len(seeds)}); {heldout} − {randomised}, paired: "
                  f"{_paired(own, camera)[0]} m.")
    else:
        first += f"**{NOT_MEASURED}** (no seed evaluated in both looks under {where})."
    second = f"Does it drive the {heldout} look at least as far as Coll-Q-Net trained on the same data? "
    text, diff = _paired(coll, camera)
    if diff:
        ahead = sum(d >= 0 for d in diff)
        second += (f"**{'yes' if np.mean(diff) >= 0 else 'no'}**: camera-label Depth-Q-Net − Coll-Q-Net "
                   f"{text} m; at least as far in {ahead} of {len(diff)} seeds.")
    else:
        second += f"**{NOT_MEASURED}** (no seed with both nets evaluated under {where})."
    return [first, second]


# Issue #57's bars: a share of the colour-trained net's distance; a multiple of the labeller's colour error.
RECIPE_SHARE, LABELLER_RATIO = 0.9, 1.3


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def _agreements(out: Path, net: str, look: str, drive: str, seeds: tuple[int, ...]) -> list[float]:
    found = _agreement_records(out, net, look, drive, seeds)
    return [float(f["agreement_decisive"]) for f in found if f.get("agreement_decisive") is not None]


def _labeller_median(out: Path, look: str, drive: str, method: str) -> float | None:
    path = error_path(out, look, drive, method)
    median = read_json(path)["nearest"]["median"] if path.is_file() else None
    return None if median is None else float(median)


def recipe_answers(out: Path, runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
                   train_looks: tuple[str, ...] = TRAIN_LOOKS, drive_looks: tuple[str, ...] = DRIVE_LOOKS,
                   method: str = PINNED_METHOD) -> list[str]:
    """Issue #57's "done when" of each training look or recipe but the reference (the colour look's
    camera-label Depth-Q-Net driven in colours), answered from what OUT holds: its camera-label
    Depth-Q-Net's distance in every driving look against `RECIPE_SHARE` of the reference's and
    against its own Coll-Q-Net's (the farther of its own weights and `REWEIGHED`'s); its agreement
    with the depth oracle on decisive steps in the textured and held-out looks against the
    colour-trained LiDAR-label net's in colours (`diagnose`); its labeller's error there against
    `LABELLER_RATIO` × its error in colours; its nets' dead outputs."""
    reference = _mean(_d2c(_distances(out, "camera", COLOURS, COLOURS, seeds)))
    agreed = _mean(_agreements(out, "depth", COLOURS, COLOURS, seeds))
    lines = []
    for look in train_looks:
        if look == COLOURS:
            continue
        drives, shares, ahead = [], [], 0
        for drive in drive_looks:
            camera = _mean(_d2c(_distances(out, "camera", look, drive, seeds)))
            colls = [_mean(_d2c(_distances(out, key, look, drive, seeds))) for key in ("coll", *REWEIGHED)]
            coll = max((c for c in colls if c is not None), default=None)  # its best chance
            ahead += camera is not None and coll is not None and camera > coll
            if camera is None or reference is None:
                drives.append(f"{drive} –")
                continue
            shares.append(camera / reference)
            drives.append(f"{drive} {camera / reference:.0%}")
        held = len(shares) == len(drive_looks) and min(shares) >= RECIPE_SHARE and ahead == len(drive_looks)
        first = f"**{'yes' if held else 'no'}**" if len(shares) == len(drive_looks) else f"**{NOT_MEASURED}**"
        text = [f"`{look}`: drives every look at ≥ {RECIPE_SHARE:.0%} of the colour-trained camera-label "
                f"net's distance in colours ({'–' if reference is None else f'{reference:.2f} m'}) and "
                f"farther than its Coll-Q-Net? {first} ({', '.join(drives)}; farther than its Coll-Q-Net "
                f"in {ahead} of {len(drive_looks)})."]
        hard = [d for d in (TEXTURED, HELDOUT) if d in drive_looks]
        agreement = {d: _mean(_agreements(out, "camera", look, d, seeds)) for d in hard}
        if agreed is not None and hard and all(v is not None for v in agreement.values()):
            verdict = "yes" if all(v >= agreed for v in agreement.values()) else "no"
            cells = ", ".join(f"{d} {v:.1%}" for d, v in agreement.items())
            text.append(f"Takes the depth oracle's best action on decisive steps as often as the "
                        f"colour-trained LiDAR-label net in colours ({agreed:.1%})? **{verdict}** ({cells}).")
        else:
            text.append(f"Agreement on decisive steps: **{NOT_MEASURED}** (`{PROG} diagnose`).")
        own = _labeller_median(out, look, COLOURS, method)
        errors = {d: _labeller_median(out, look, d, method) for d in hard}
        if own and hard and all(v is not None for v in errors.values()):
            verdict = "yes" if all(v <= LABELLER_RATIO * own for v in errors.values()) else "no"
            cells = ", ".join(f"{d} {v / own:.2f} ×" for d, v in errors.items())
            text.append(f"Its labeller's error within {LABELLER_RATIO} × its error in colours ({own:.3f} m)? "
                        f"**{verdict}** ({cells}).")
        else:
            text.append(f"Its labeller's error per look: **{NOT_MEASURED}**.")
        dead = []
        for seed in seeds:
            for net in ("depth", "camera"):
                folder = checkpoints(out, look, runs, seed, method)[net]
                if (folder / CONFIG).is_file() and (found := count_dead_outputs(folder)) is not None:
                    dead.append(len(found.dead))
        text.append(f"Dead outputs: {', '.join(map(str, dead)) if dead else NOT_MEASURED} (per Depth-Q-Net, "
                    "LiDAR then camera labels per seed, on its validation frames).")
        lines.append(" ".join(text))
    return lines


def distance_figure(path: Path, out: Path, seeds: tuple[int, ...] = (0, 1, 2),
                    train_looks: tuple[str, ...] = TRAIN_LOOKS, drive_looks: tuple[str, ...] = DRIVE_LOOKS
                    ) -> None:
    """Per net a panel: for each driving look a bar per training look or recipe, the mean distance to
    the first collision over the seeds evaluated, each seed's a dot."""
    figure_, axes = plt.subplots(1, len(DRIVEN), figsize=(4.8 * len(DRIVEN), 3.6), sharey=True, squeeze=False)
    width = 0.8 / len(train_looks)
    x = np.arange(len(drive_looks))
    for ax, (net, label) in zip(axes[0], DRIVEN.items(), strict=True):
        for k, look in enumerate(train_looks):
            values = [_d2c(_distances(out, net, look, drive, seeds)) for drive in drive_looks]
            where = x + (k - (len(train_looks) - 1) / 2) * width
            ax.bar(where, [np.mean(v) if v else 0.0 for v in values], width, label=look)
            for at, seeds_of in zip(where, values, strict=True):
                ax.plot([at] * len(seeds_of), seeds_of, "k.", markersize=3)
        ax.set_xticks(x, drive_looks)
        ax.set_title(label)
        ax.set_xlabel("driven in")
    axes[0][0].set_ylabel("m to the first collision")
    axes[0][-1].legend(title="trained", fontsize="small")
    figure_.tight_layout()
    buffer = io.BytesIO()
    figure_.savefig(buffer, format="png", dpi=110)
    plt.close(figure_)
    atomic_write_bytes(path, buffer.getvalue())


def _canyons(out: Path) -> str:
    """The canyons OUT's evaluations drove in, from the first one found ("not yet measured" for none)."""
    for path in sorted(Path(out).glob("*/eval_*/*/summary.json")):
        canyons = read_json(path)["config"]["canyons"]
        return f"{len(canyons)} canyons, {canyons[0]} … {canyons[-1]}" if len(canyons) > 1 else canyons[0]
    return NOT_MEASURED


def report(out: Path, runs: int = 500, seeds: tuple[int, ...] = (0, 1, 2),
           train_looks: tuple[str, ...] = TRAIN_LOOKS, drive_looks: tuple[str, ...] = DRIVE_LOOKS,
           method: str = PINNED_METHOD) -> Path:
    """OUT/report.md and the self-contained OUT/report.html, from what OUT holds: the issue's answers,
    the nets' table, the held-out look's cost and what textured training gives back, the labellers'
    errors per look, the same pose in every look (OUT/looks.png, drawn once)."""
    out = Path(out)
    if not out.is_dir():
        raise ConfigError(f"{out}: no such folder (make it with `{PROG} run {out}`)")
    if not (out / "looks.png").is_file():
        figure(out / "looks.png")
    intro = (f"{runs} training runs per net, seeds {','.join(map(str, seeds))}; driven in: {_canyons(out)}. "
             "Distance to the first collision, mean [95 % Student-t interval] over seeds; "
             "paired differences by training seed. The issue asks its answers of the hard `eval` canyons, "
             "500 runs, 3 seeds.")
    diagnosed = [r for r in diagnosis_rows(out, seeds, train_looks, drive_looks) if r["seeds"] != "0"]
    distance_figure(out / "distance_by_look.png", out, seeds, train_looks, drive_looks)
    sections = [
        ("Done when (issue #45)", answers(out, seeds), None),
        ("Done when (issue #57), per recipe",
         recipe_answers(out, runs, seeds, train_looks, drive_looks, method), None),
        ("Every net × training look × driving look", [],
         table_rows(out, runs, seeds, train_looks, drive_looks)),
        ("The held-out look's cost, and what textured training gives back", [], transfer_rows(out, seeds)),
        ("How well each net predicts in each look",
         ["Each net's training loss on each driving look's validation runs (`depthq.train.offline_metric`, "
          "the Depth-Q-Nets' absolute difference against the LiDAR's bins whatever their labels), apart "
          "from how it drives there."], prediction_rows(out, seeds, train_looks, drive_looks)),
        ("What training carries to new runs of its look",
         ["Validation loss of each net in its training look's validation runs, by epoch (the checkpoint's "
          "metrics.csv)."], learning_rows(out, runs, seeds, train_looks, method)),
        ("Along the nets' own runs, in the choice canyons",
         [f"`{PROG} diagnose`: each net driven in the `val` canyons of each look, and at every step of its "
          "runs the depth oracle's action (the true next bins of each candidate) and the net's scores "
          "from the frame rendered again there. Decisive: the candidates' true scores differ by more "
          "than 1 cm." if diagnosed else f"{NOT_MEASURED} (`{PROG} diagnose {out}`)"],
         diagnosed or None),
        ("The labellers' error per look", [f"The {method} labeller trained in each look against the LiDAR's "
                                           "bins: median [mean] absolute error of each frame's nearest bin."],
         labeller_rows(out, train_looks, drive_looks, method)),
    ]
    pose = "The same pose in every look"
    lines = [f"# The looks experiment: {out.name}", "", intro, ""]
    for title, texts, rows in sections:
        lines += [f"## {title}", ""]
        if rows is None:
            lines += [*(f"- {t}" for t in texts), ""]
        else:
            lines += [*(f"{t}\n" for t in texts), markdown(rows)]
    drawn = "Distance per driving look"
    lines += [f"## {drawn}", "", f"![{drawn}](distance_by_look.png)", ""]
    lines += [f"## {pose}", "", f"![{pose}](looks.png)", ""]
    atomic_write_bytes(out / "report.md", "\n".join(lines).encode())
    html_sections = [(title, "".join(f"<p>{html.escape(t.replace('**', ''))}</p>" for t in texts)
                      + (page.table(rows) if rows is not None else "")) for title, texts, rows in sections]
    html_sections[0] = (html_sections[0][0], f"<p>{html.escape(intro)}</p>" + html_sections[0][1])
    html_sections.append((drawn, page.img(out / "distance_by_look.png", drawn.lower())))
    html_sections.append((pose, page.img(out / "looks.png", pose.lower())))
    atomic_write_bytes(out / "report.html", page.render(f"depthq looks experiment — {out.name}",
                                                        html_sections).encode())
    return out / "report.md"


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
    common.add_argument("--train-looks", default=",".join(TRAIN_LOOKS),
                        help=f"recipes the nets learn by: a look's name (that look alone) or one of "
                             f"{', '.join(RECIPES)}")
    common.add_argument("--drive-looks", default=",".join(DRIVE_LOOKS),
                        help=f"looks every net drives in (`{GENERATED}`: a folder of images the experiment "
                             "generates, seen by no net)")
    common.add_argument("--method", default=PINNED_METHOD,
                        help=f"the camera labeller (default: {PINNED_METHOD})")
    go = actions.add_parser("run", parents=[common], help="sweeps, camera labels, evaluations (resumed)")
    go.add_argument("--preset", default="hard", help="the sweep preset the training follows (default: hard)")
    go.add_argument("--canyons", default="hard/eval", help="the canyons of the table (default: hard/eval)")
    go.add_argument("--choose", default=CHOOSE, help=f"the canyons of every choice (default: {CHOOSE})")
    go.add_argument("--val-runs", type=int, default=VAL_RUNS,
                    help=f"validation runs per driving look, the labellers' test (default: {VAL_RUNS})")
    go.add_argument("--time-limit", type=float, default=None, help="seconds per evaluation run")
    go.add_argument("--labeller-set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a LabellerConfig setting, as camera_labels takes it; repeatable")
    go.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a training setting of every Q-net, one value; repeatable")
    go.add_argument("--workers", type=int, default=2, help="processes per evaluation (default: 2)")
    go.add_argument("--device", default="auto", help="torch device (default: auto)")
    go.add_argument("--no-progress", action="store_true", help="no progress bars")
    go.add_argument("--train-only", action="store_true",
                    help="train every recipe, drive nothing in --canyons (choose first, with diagnose)")
    why = actions.add_parser("diagnose", parents=[common],
                             help="the nets driven in the choice canyons of each look, their actions "
                                  "and scores checked against the depth oracle's along their runs (resumed)")
    why.add_argument("--nets", default=",".join(DIAGNOSE_NETS),
                     help=f"the nets to diagnose (default: {','.join(DIAGNOSE_NETS)})")
    why.add_argument("--choose", default=CHOOSE, help=f"the canyons to drive (default: {CHOOSE})")
    why.add_argument("--time-limit", type=float, default=None, help="seconds per evaluation run")
    why.add_argument("--workers", type=int, default=2, help="processes per evaluation (default: 2)")
    why.add_argument("--device", default="auto", help="torch device (default: auto)")
    why.add_argument("--no-progress", action="store_true", help="no progress bars")
    actions.add_parser("table", parents=[common], help="the Markdown tables of what OUT holds")
    actions.add_parser("report", parents=[common],
                       help="OUT/report.md and OUT/report.html: the tables, the issue's answers, the figure")
    args = parser.parse_args(argv)

    def work() -> int:
        if args.action == "figure":
            figure(args.docs / "looks.png")
            print(f"wrote {args.docs / 'looks.png'}")
            return 0
        seeds = parse_ints(args.seeds, "--seeds")
        train_looks, drive_looks = _looks(args.train_looks), _looks(args.drive_looks)
        if args.action == "table":
            print(table(args.out, args.runs, seeds, train_looks, drive_looks, args.method))
            return 0
        if args.action != "run" and not args.out.is_dir():
            raise ConfigError(f"{args.out}: no such folder (make it with `{PROG} run {args.out}`)")
        with exclusive(args.out, "OUT"):  # one writer per experiment folder
            return write(seeds, train_looks, drive_looks)

    def write(seeds: tuple[int, ...], train_looks: tuple[str, ...], drive_looks: tuple[str, ...]) -> int:
        if args.action == "diagnose":
            return diagnose(args.out, runs=args.runs, seeds=seeds, train_looks=train_looks,
                            drive_looks=drive_looks, nets=_looks(args.nets), choose=args.choose,
                            method=args.method, time_limit_s=args.time_limit, workers=args.workers,
                            device=args.device, progress=not args.no_progress)
        if args.action == "report":
            print(f"wrote {report(args.out, args.runs, seeds, train_looks, drive_looks, args.method)}")
            return 0
        return run(args.out, preset=args.preset, runs=args.runs, seeds=seeds, canyons=args.canyons,
                   choose=args.choose, train_looks=train_looks, drive_looks=drive_looks, method=args.method,
                   time_limit_s=args.time_limit,
                   labeller_settings=camera_labels.parse_settings(args.labeller_set, "--labeller-set"),
                   training=camera_labels.parse_settings(args.set, "--set"), val_runs=args.val_runs,
                   workers=args.workers, device=args.device, progress=not args.no_progress,
                   train_only=args.train_only)

    return guarded(PROG, work)


if __name__ == "__main__":
    sys.exit(main())
