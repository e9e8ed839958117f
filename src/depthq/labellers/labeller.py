"""The camera labeller: depth bins estimated from one frame, learnt on another canyon family's LiDAR.

The stand-in for an off-the-shelf monocular depth model (issue #32, docs/design.md#camera-labels): the
frozen default trunk's feature → FC hidden + ReLU → FC 26, the read-out of the depth-first head's
`perceive`, trained with an L1 loss on the current LiDAR bins of a dataset of ANOTHER canyon family
(an invalid bin as the 2 m clip, as that head's perception target). It used a depth sensor, elsewhere:
no depth of the canyons it labels. Applied to a dataset (`depthq label`), it writes every frame's 26
bins, clipped to [0, 2] m, into the run files (`depthq.data.camera_labels`). The floor labeller
(`depthq.labellers.floor`) and the monodepth labeller (`depthq.labellers.monodepth`) learn from the camera and
odometry alone instead; their folders have the same files, with their own settings (docs/formats.md).

Its folder (written by `depthq labeller`):

    config.json           format "depthq-labeller" 1, provenance, the LabellerConfig, name, fingerprint,
                          trunk, input_size, n_bins, bins (the geometry its bins follow), source (the
                          dataset it learnt from: path, fingerprint, family), losses (the training loss
                          over each tenth of the steps), val_l1 (on the source's val runs); written last
    weights.safetensors   the read-out's weights, with the SHA-256 of their bytes (never a pickle)

Its fingerprint, the SHA-256 of its weights' digest and of what fixes its output (trunk, input size,
bins), is what a run file's labels record: equal fingerprints, equal labels.
"""

from __future__ import annotations

import hashlib
import json
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from torch import nn

from depthq.blocks.device import resolve_device
from depthq.blocks.losses import DEPTH_CLIP
from depthq.blocks.optim import make_optimizer
from depthq.blocks.trunk import DEFAULT_TRUNK, INPUT_SIZE, TRUNKS, Trunk, build_trunk, preprocess
from depthq.checkpoint import DIGEST, read_weights, weights_bytes
from depthq.checksum import read_checked_json, write_checked_json
from depthq.configio import (
    OMIT_DEFAULT,
    atomic_write_bytes,
    check_choices,
    check_seed,
    from_dict,
    provenance,
    to_dict,
)
from depthq.data.camera_labels import CameraLabels
from depthq.data.manifest import Dataset, RunEntry
from depthq.data.run import Run
from depthq.data.runfile import RunReader
from depthq.data.views import run_then_frame
from depthq.errors import ConfigError, DataError
from depthq.labellers import floor, monodepth
from depthq.parallel import cores
from depthq.progress import Bar
from depthq.sim.sensors import BinConfig
from depthq.train.features import BATCH, FeatureTable, load_features

FORMAT = "depthq-labeller"
FORMAT_VERSION = 1
CONFIG = "config.json"
WEIGHTS = "weights.safetensors"
LOG_BLOCKS = 10  # the training loss is recorded as the mean over each tenth of the steps


Method = Literal["floor", "perception", "monodepth"]
PoolLooks = Literal["collected", "every_look"]
METHODS: tuple[str, ...] = typing.get_args(Method)
# The trunks a perception labeller reads: frozen ones, whose features are cached in its dataset.
FrozenTrunk = Literal[tuple(name for name, spec in TRUNKS.items() if spec.frozen)]  # type: ignore[valid-type]
# The method's defaults of the settings a LabellerConfig leaves None: (scale, steps, batch_size, lr);
# perception uses no scale (its records hold the 2 they always held).
_DEFAULTS = {"floor": (2, 600, 8, 1e-3), "perception": (2, 4000, 64, 0.1), "monodepth": (4, 1500, 8, 1e-3)}
# The methods that learn from the camera and odometry alone and read distances through the camera's
# geometry: they may label the dataset they learnt on, one of the same camera and robot.
CAMERA_METHODS = ("floor", "monodepth")


@dataclass(frozen=True)
class LabellerConfig:
    """One labeller training on `data` (docs/design.md#camera-labels)."""

    # The dataset it learns from: for "floor" and "monodepth" its camera and odometry (it may be the
    # dataset to label); for "perception" its LiDAR (another canyon family's than the datasets it will
    # label).
    data: str
    # How a frame becomes bins: "monodepth" (camera and odometry only: a depth net learnt by warping each
    # frame's neighbours into it, Monodepth2's self-supervision), "floor" (camera and odometry only: where
    # the floor ends, learnt from the robot's future footprint) or "perception" (a read-out of the
    # trunk's feature learnt on another family's LiDAR: a stand-in for an off-the-shelf depth model).
    method: Method = "monodepth"
    # perception: a frozen trunk (its features are cached in `data`); the default Depth-Q-Net's.
    trunk: FrozenTrunk = DEFAULT_TRUNK
    # perception: side of the square image the trunk sees, in pixels.
    input_size: int = INPUT_SIZE
    # perception: width of the read-out's hidden layer (the depth-first head's).
    hidden: int = 4096
    # floor, monodepth: frames are box-averaged by this factor before the net (2: 205 × 154 pixels);
    # none: the method's (floor 2; monodepth 4, 102 × 77: its loss warps every frame at four scales).
    scale: int | None = None
    # floor: channels of the floor net's layers; monodepth: of the depth net's first level.
    width: int = 16
    # floor: the context branch, the colours of the floor ahead shifting the first layer (what floor looks
    # like differs canyon by canyon in the hard family's randomised look).
    context: bool = True
    # floor: the next poses whose footprint is free floor (12: 3 s at 4 Hz, 1.5 m at 0.5 m/s).
    lookahead: int = 12
    # floor: floor nearer than this (m ahead of the camera) is neither learnt nor judged.
    nearest: float = 0.3
    # floor, monodepth: each frame's readings fused with those of the frames of the last memory_s
    # seconds, moved by odometry (nearest wins): obstacles lost close up stay where earlier frames saw
    # them; 0: off.
    memory_s: float = 2.0
    # floor, monodepth: random frames of each training run in the training pool (held in memory,
    # reduced; monodepth: each with its two neighbours).
    pool_frames: int = 6
    # floor, monodepth: the first collected training runs whose frames make the pool.
    pool_runs: int = 300
    # floor, monodepth: the pool's looks in a re-rendered dataset (`depthq dataset rerender`): "collected"
    # (the runs as collected) or "every_look" (each with its re-renders). "collected" read depth better
    # on `val` (docs/research/looks.md#labeller-pool).
    pool: PoolLooks = field(default="collected", metadata=OMIT_DEFAULT)
    # monodepth: the nearest depth the net can predict, m.
    min_depth: float = 0.1
    # monodepth: the farthest depth the net can predict, m: beyond the bins' clip, as the floor and the
    # walls down the canyon are (capped at the clip, they would warp wrongly).
    max_depth: float = 10.0
    # monodepth: weight of the edge-aware smoothness of the disparity against the photometric error.
    smoothness: float = 1e-3
    # monodepth: how the photometric loss brings each neighbouring frame to the frame's brightness
    # before comparing them, per frame pair and colour channel (a robot camera's auto-exposure and white
    # balance change between frames): "none", "gain" (the ratio of their means) or "affine" (a gain and
    # a bias, least squares over the pixels the warp sees).
    brightness: monodepth.Brightness = "none"
    # Optimiser steps; none: the method's (floor 600, perception 4000 = a training's 40 × 100,
    # monodepth 1500).
    steps: int | None = None
    # Frames per step; none: the method's (floor 8, perception 64, monodepth 8 triplets).
    batch_size: int | None = None
    # Learning rate; none: the method's (floor, monodepth: Adam's 1e-3; perception: Adadelta's 0.1,
    # the heads').
    lr: float | None = None
    # Seeds the initialisation, the pool and the batches.
    seed: int = 0

    def __post_init__(self) -> None:
        check_seed(self.seed)
        if not isinstance(self.data, str) or not self.data:
            raise ConfigError(f"labeller.data must be a dataset folder, got {self.data!r}")
        check_choices(self, "labeller")  # method, trunk, brightness, pool
        for name, value in zip(("scale", "steps", "batch_size", "lr"), _DEFAULTS[self.method], strict=True):
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        for name, low in (("input_size", 1), ("hidden", 1), ("scale", 1), ("width", 1), ("lookahead", 1),
                          ("pool_frames", 1), ("pool_runs", 1), ("steps", 1), ("batch_size", 1), ("seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ConfigError(f"labeller.{name} must be an integer >= {low}, got {value!r}")
        for name in ("lr", "nearest", "min_depth", "max_depth"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < np.inf:
                raise ConfigError(f"labeller.{name} must be a finite number > 0, got {value!r}")
        m = self.memory_s
        if isinstance(m, bool) or not isinstance(m, int | float) or not 0 <= m < np.inf:
            raise ConfigError(f"labeller.memory_s must be a finite number of seconds >= 0, got {m!r}")
        if not self.min_depth < self.max_depth:
            raise ConfigError(f"labeller.max_depth must be above min_depth {self.min_depth!r}, got "
                              f"{self.max_depth!r}")
        w = self.smoothness
        if isinstance(w, bool) or not isinstance(w, int | float) or not 0 <= w < np.inf:
            raise ConfigError(f"labeller.smoothness must be a finite number >= 0, got {w!r}")


class Perception(nn.Module):
    """Feature (B, D) → bins (B, n_bins), unbounded: the depth-first head's perception read-out."""

    def __init__(self, feature_dim: int, hidden: int, n_bins: int) -> None:
        super().__init__()
        self.hidden = nn.Linear(feature_dim, hidden)
        self.current = nn.Linear(hidden, n_bins)
        for layer in (self.hidden, self.current):  # Glorot, as every head
            nn.init.xavier_uniform_(layer.weight)
            nn.init.zeros_(layer.bias)

    def forward(self, feature: torch.Tensor) -> torch.Tensor:
        return self.current(torch.relu(self.hidden(feature)))


class PerceptionEstimate:
    """A run → bins (N, n_bins), clipped to [0, DEPTH_CLIP] m: each frame through the trunk, then read-out."""

    def __init__(self, net: Perception, trunk: Trunk, input_size: int) -> None:
        self.net, self.trunk, self.input_size = net, trunk, input_size

    @torch.inference_mode()
    def __call__(self, run: Run) -> np.ndarray:
        frames = run.images
        bins = [self.net(self.trunk(preprocess(frames[i : i + BATCH], self.input_size)))
                for i in range(0, len(frames), BATCH)]
        return torch.cat(bins).clamp(0.0, DEPTH_CLIP).numpy().astype(np.float32)


@dataclass(frozen=True, eq=False)
class Labeller:
    """A trained labeller ready to label frames (`load_labeller`)."""

    estimate: Callable[[Run], np.ndarray]  # a run read with its images → bins (N, n_bins) float32
    fingerprint: str
    record: dict[str, Any]  # its config.json

    def label(self, reader: RunReader) -> CameraLabels:
        """A run's camera labels: every stored frame's estimated bins."""
        return CameraLabels(self.estimate(reader.run(images=True)), self.record["name"],
                            self.fingerprint)


def bin_geometry(dataset: Dataset) -> dict[str, Any]:
    """The depth bins' config of a dataset (a robot's recording is resampled to the default's)."""
    env = dataset.config.get("env")
    return to_dict(BinConfig()) if env is None else env["bins"]


def train_labeller(config: LabellerConfig, out: Path, progress: bool = True, device: str = "auto") -> Path:
    """Train `config` into the folder `out` and return it; a folder holding this labeller is returned as
    it is, one holding anything else is a ConfigError (nothing is written before the data is checked).
    `device`: see `depthq.blocks.device`."""
    out, device = Path(out), resolve_device(device)
    if (out / CONFIG).is_file():
        if _config_record(read_record(out)) != to_dict(config):
            raise ConfigError(f"--out {out} holds another labeller (config.json differs); use another folder")
        return out
    if out.exists() and any(out.iterdir()):
        raise ConfigError(f"--out {out}: exists, is not empty and holds no labeller ({CONFIG} missing)")
    dataset = Dataset.open(Path(config.data))
    for split in ("train", "val"):
        if not dataset.entries(split):
            raise ConfigError(f"{dataset.root} has no {split} runs to train a labeller on")
    torch.set_num_threads(cores())
    torch.manual_seed(config.seed)
    bins = bin_geometry(dataset)
    if config.method == "floor":
        geo = floor.geometry(dataset.config.get("env"), config.scale)
        net, losses, val = floor.train(dataset, geo, config, progress, device)
        identity = floor.identity(config, floor.geometry_record(geo), bins)
        results = {"val_loss": round(val, 6)}
    elif config.method == "monodepth":
        geo = floor.geometry(dataset.config.get("env"), config.scale)
        net, losses, val = monodepth.train(dataset, geo, config, progress, device)
        identity = monodepth.identity(config, floor.geometry_record(geo), bins)
        results = {"val_loss": round(val, 6)}
    else:
        net, losses, val = _train_perception(dataset, config, progress, device)
        identity = _identity(config.trunk, config.input_size, bins)
        results = {"val_l1": round(val, 6)}
    tensors = {k: v.detach().cpu().contiguous() for k, v in net.state_dict().items()}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / WEIGHTS, weights_bytes(tensors))
    blocks = np.array_split(np.asarray(losses), min(LOG_BLOCKS, len(losses)))
    write_checked_json(out / CONFIG, {
        "format": FORMAT, "format_version": FORMAT_VERSION, "provenance": provenance(),
        "config": to_dict(config), "name": config.method, **identity, "n_bins": BinConfig(**bins).n_bins,
        "fingerprint": _fingerprint(identity, read_weights(out / WEIGHTS)[1][DIGEST]),
        "source": {"path": str(dataset.root.resolve()), "fingerprint": dataset.fingerprint(),
                   "family": dataset.family()},
        "losses": [round(float(b.mean()), 6) for b in blocks], **results,
    })
    return out


def _train_perception(dataset: Dataset, config: LabellerConfig, progress: bool, device: torch.device
                      ) -> tuple[nn.Module, list[float], float]:
    """The perception read-out learnt on `dataset`'s current LiDAR bins: (net, losses, val L1 in m)."""
    table = load_features(dataset, config.trunk, config.input_size, progress, device)
    train, val = (_frames(dataset, table, split) for split in ("train", "val"))
    features = {split: torch.from_numpy(table.features[rows]).float()
                for split, (rows, _, _) in (("train", train), ("val", val))}
    net = Perception(TRUNKS[config.trunk].feature_dim, config.hidden, train[1].shape[1]).to(device)
    optimizer = make_optimizer(net, config.lr, weight_decay=0.0)
    rng = np.random.default_rng(config.seed)
    losses = []
    for _ in Bar(range(config.steps), desc="train labeller", unit="step", disable=not progress):
        idx = torch.from_numpy(run_then_frame(train[2], config.batch_size, rng))
        loss = (net(features["train"][idx].to(device)) - train[1][idx].to(device)).abs().mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    with torch.no_grad():
        val_l1 = (net(features["val"].to(device)).cpu() - val[1]).abs().mean().item()
    return net.cpu(), losses, val_l1


def _config_record(record: dict[str, Any]) -> dict[str, Any]:
    """A labeller record's config, upgraded: one written before `method` existed is a perception one, a
    floor one written before `context` existed has none, one written before `brightness` existed
    learnt without brightness compensation ("none")."""
    config = dict(record["config"])
    config.setdefault("method", "perception")
    if config["method"] == "floor":
        config.setdefault("context", False)
    config.setdefault("brightness", "none")
    return to_dict(from_dict(LabellerConfig, config))


def read_record(folder: Path) -> dict[str, Any]:
    """A labeller folder's config.json, its checksum checked (`depthq.checksum`)."""
    return read_checked_json(Path(folder) / CONFIG, "restore the labeller folder from a copy, or train it "
                             "again (a config is never edited by hand)")


def load_labeller(folder: Path) -> Labeller:
    """The labeller in `folder`; a missing or foreign folder, or weights that fail their SHA-256, is an
    error naming the file."""
    folder = Path(folder)
    path = folder / CONFIG
    if not path.is_file():
        raise ConfigError(f"--labeller {folder}: not a labeller folder (no {CONFIG}; make one with "
                          "`depthq labeller --data DATASET --out FOLDER`)")
    record = read_record(folder)
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise ConfigError(f"{path}: not a {FORMAT} config")
    if record.get("format_version") != FORMAT_VERSION:
        raise ConfigError(f"{path}: labeller format version {record.get('format_version')!r}, this depthq "
                          f"reads {FORMAT_VERSION}")
    config = from_dict(LabellerConfig, _config_record(record))
    tensors, metadata = read_weights(folder / WEIGHTS)
    if config.method == "floor":
        net: nn.Module = floor.FloorNet(config.width, config.context)
        identity = floor.identity(config, record["geometry"], record["bins"])
    elif config.method == "monodepth":
        net = monodepth.DepthNet(config.width)
        identity = monodepth.identity(config, record["geometry"], record["bins"])
    else:
        net = Perception(TRUNKS[config.trunk].feature_dim, config.hidden, int(record["n_bins"]))
        identity = _identity(config.trunk, config.input_size, record["bins"])
    try:
        net.load_state_dict(tensors)
    except RuntimeError as err:
        raise ConfigError(f"{folder / WEIGHTS}: weights do not fit its {CONFIG} ({err})") from err
    net.eval()
    if config.method in CAMERA_METHODS:
        geo = floor.geometry(floor.env_of(record["geometry"], record["bins"]), config.scale)
    if config.method == "floor":
        estimate: Callable[[Run], np.ndarray] = floor.FloorEstimate(net, geo, config.nearest, config.memory_s)
    elif config.method == "monodepth":
        depths = (config.min_depth, config.max_depth)
        estimate = monodepth.MonodepthEstimate(net, geo, depths, config.memory_s)
    else:
        estimate = PerceptionEstimate(net, build_trunk(config.trunk), config.input_size)
    return Labeller(estimate, _fingerprint(identity, metadata[DIGEST]), record)


def _frames(dataset: Dataset, table: FeatureTable, split: str) -> tuple[np.ndarray, torch.Tensor, np.ndarray]:
    """Every frame of a split's runs: feature-cache rows (F,), current LiDAR bins (F, n_bins) with an
    invalid bin as the clip, and the runs' offsets (R + 1,) for `run_then_frame`."""
    entries = dataset.entries(split)
    rows = np.concatenate([table.runs[e.name][0] + np.arange(e.n_frames) for e in entries])
    bins = np.concatenate([dataset.read_run(e, images=False).bins for e in entries])
    offsets = np.concatenate([[0], np.cumsum([e.n_frames for e in entries])])
    return rows, torch.from_numpy(np.nan_to_num(bins, nan=DEPTH_CLIP)), offsets


def _identity(trunk: str, input_size: int, bins: dict[str, Any]) -> dict[str, Any]:
    """What fixes a labeller's output besides its weights."""
    return {"trunk": trunk, "input_size": input_size, "bins": bins}


def _fingerprint(identity: dict[str, Any], weights_digest: str) -> str:
    text = json.dumps({**identity, "weights": weights_digest}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def check_applicable(labeller: Labeller, dataset: Dataset) -> None:
    """ConfigError unless `labeller` may label `dataset`: bins of the same geometry; a floor or monodepth
    labeller, the same camera and robot; a perception labeller, learnt on another canyon family (no
    depth of the canyons it labels; a robot's recording is no canyon family)."""
    record = labeller.record
    if record["bins"] != bin_geometry(dataset):
        raise ConfigError(f"labeller bins {record['bins']} differ from {dataset.root}'s bins "
                          f"{bin_geometry(dataset)}: its labels would not be in this dataset's geometry")
    if record["name"] in CAMERA_METHODS:
        own = floor.geometry_record(floor.geometry(dataset.config.get("env"), record["scale"]))
        if own != record["geometry"]:
            what = "floor rows" if record["name"] == "floor" else "depths and odometry"
            raise ConfigError(f"labeller camera and robot {record['geometry']} differ from {dataset.root}'s "
                              f"{own}: its {what} would give wrong distances")
        return
    source, target = record["source"]["family"], dataset.family()
    if source == target:
        raise ConfigError(
            f"the labeller learnt from the {source!r} family's LiDAR ({record['source']['path']}), and "
            f"{dataset.root} is of the {target!r} family too: train one on another family's dataset, so "
            "that no depth of these canyons goes into their labels"
        )


def label_dataset(dataset: Dataset, labeller: Labeller, replace: bool = False, progress: bool = True
                  ) -> tuple[int, int]:
    """Write `labeller`'s camera labels into every run of `dataset` that lacks them; returns (runs
    written, runs that held them already). Every check runs before the first run is written: a labeller
    that may not label this dataset (`check_applicable`), a run labelled by another labeller (unless
    `replace`), a file that fails its manifest check. A run file left by a labelling stopped between
    the file's rename and the manifest's is taken as it is (`Dataset.adopt_labelled`)."""
    check_applicable(labeller, dataset)
    pending, kept = [], 0
    for entry in dataset.entries():
        try:
            held = _held(dataset, entry)
        except DataError:
            adopted = dataset.adopt_labelled(entry)
            if adopted is None:
                raise
            held = _held(dataset, adopted)
        if held is not None and held.fingerprint == labeller.fingerprint:
            kept += 1
        elif held is not None and not replace:
            raise ConfigError(
                f"{dataset.path(entry)} holds camera labels of another labeller ({held.labeller}, "
                f"fingerprint {held.fingerprint[:16]}…; this one's is {labeller.fingerprint[:16]}…): "
                "add --replace to relabel every run with this one"
            )
        else:
            pending.append((entry.split, entry.index))
    for key in Bar(pending, desc="label", unit="run", disable=not progress):
        entry = dataset.entry(*key)  # as adopted, if it was
        with dataset.reader(entry) as reader:
            labels = labeller.label(reader)
        dataset.set_camera_labels(entry, labels)
    return len(pending), kept


def _held(dataset: Dataset, entry: RunEntry) -> CameraLabels | None:
    with dataset.reader(entry) as reader:
        return reader.camera_labels()
