"""The checkpoint folder a training writes, in one place: opened once (checked against the training,
resumed), then one `TrainingCheckpoint.write_epoch` per epoch, which writes every file of that epoch.

Layout of OUT/ (the format of config.json and the weight files: `depthq.checkpoint.format`; every file
but the TensorBoard log is written atomically: temporary sibling, rename; a killed training's
temporaries are removed when it resumes):

    config.json              what was trained, on which data, for which policy
    best.safetensors         weights at the epoch of lowest validation loss: the head's ("head.*",
    last.safetensors         its fitted feature projection's buffers "head.projection.*" included),
                             and the trunk's ("trunk.*") when it is trained (a tuned one's late
                             stages only); a frozen trunk, or a tuned one's frozen stages, is not
                             stored: it is rebuilt from the package's pretrained weights
    epoch_0040.safetensors   the weights after an epoch of `TrainConfig.snapshots` (kept on resume)
    average.safetensors      the mean of the weights after each epoch of the training's last
                             fraction `TrainConfig.average` so far (from its first epoch on)
    best.json, last.json     epoch and metrics of those weights (epoch_0040.json likewise; average.json:
                             the epochs averaged, their count, the mean's validation loss), each with
                             its checksum (`depthq.checkpoint.format.write_sidecar`)
    metrics.csv              epoch, train_loss, val_loss, val_loss_std, seconds (one row per epoch;
                             the seconds, a timing, are a log: no other file holds one)
    last_state.safetensors   everything a resume needs, in one file so it is consistent: weights
                             ("model.*"), optimizer state ("optim.<param>.<key>"), torch RNG
                             ("rng.torch"), the weight average so far ("average.*"), and in its
                             metadata the epoch, the NumPy sampling generator's state, the metrics
                             history, the best epoch and the average's first epoch and count
    last_state.json          a readable copy of that metadata (never read back)
    tb/                      TensorBoard event files (the trainer's log: appended, purged of stale
                             epochs on resume)

The resume state lives here, not in `depthq.train`, because it is written in the same per-epoch write
as the weights it must agree with. Which weights act is `depthq.checkpoint.acting`'s.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from safetensors import SafetensorError, safe_open
from torch.optim.swa_utils import AveragedModel

from depthq.blocks.heads import HeadConfig, QNet
from depthq.checkpoint.format import (
    CONFIG,
    DatasetRecord,
    PolicyRecord,
    dataset_record,
    load_trainable_state,
    read_config,
    read_weights,
    snapshot_stem,
    trainable_state,
    weights_bytes,
    write_record,
    write_sidecar,
)
from depthq.configio import atomic_write_bytes, field_paths, to_dict, write_json
from depthq.control.action_selection import ACTIONS
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError, DataError
from depthq.networks import Training, get_network
from depthq.sim.sensors import BinConfig

STATE = "last_state.safetensors"
METRICS = "metrics.csv"
METRIC_FIELDS = ("epoch", "train_loss", "val_loss", "val_loss_std", "seconds")


class Trained(Training, Protocol):
    """What the checkpoint reads of a training's config (`depthq.train.config.TrainConfig`, a layer
    above, has it), besides what a network reads (`depthq.networks.Training`)."""

    snapshots: tuple[int, ...]

    @property
    def learning_rate(self) -> float: ...

    @property
    def average_from(self) -> int | None: ...

    def head(self) -> HeadConfig: ...


@dataclass
class TrainState:
    """Where training stands after `epoch` epochs: one row per epoch, and the best one so far."""

    epoch: int = 0
    history: list[dict[str, float]] = field(default_factory=list)
    best: dict[str, float] | None = None


@dataclass(frozen=True)
class TrainingCheckpoint:
    """The folder `out` that the training `config` writes; `open` makes one."""

    out: Path
    config: Trained

    @classmethod
    def open(cls, out: Path, config: Trained, fingerprint: str) -> TrainingCheckpoint:
        """The checkpoint of `config` in `out`: a free folder, or one holding this training (it
        resumes). The same training means the same config but for `epochs` (a run may be extended),
        `data` (the folder may move; its content is compared by `fingerprint`) and `snapshots` (they
        do not change the training; but an epoch already trained past must have been kept).
        Anything else → ConfigError, before anything is written."""
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise ConfigError(f"--out {out}: exists and is not a folder")
        if not (out / CONFIG).is_file():
            if out.exists() and any(out.iterdir()):
                raise ConfigError(
                    f"--out {out}: exists, is not empty and holds no training ({CONFIG} missing)"
                )
            return cls(out, config)
        old = read_config(out)
        differing = settings_differing(old, config)
        if dataset_record(old).fingerprint != fingerprint:
            differing.append("data (the dataset's runs changed)")
        if differing:
            raise ConfigError(
                f"--out {out} holds a training with a different configuration (differs in: "
                f"{', '.join(differing)}); use another folder"
            )
        done = saved_epoch(out)
        kept = {e for e in config.snapshots if (out / f"{snapshot_stem(e)}.safetensors").is_file()}
        lost = [e for e in config.snapshots if e <= done and e not in kept]
        if lost:
            raise ConfigError(
                f"--out {out}: snapshots at epochs {lost} asked for, but its training is past them (epoch "
                f"{done}) and did not keep them; use another folder"
            )
        return cls(out, config)

    @property
    def epochs_done(self) -> int:
        """Epochs finished in the folder (`saved_epoch`)."""
        return saved_epoch(self.out)

    def start(
        self, dataset: Dataset, fingerprint: str, threads: int | None = None,
        labeller: dict[str, str] | None = None,
    ) -> None:
        """Make the folder, remove the temporaries a killed training left (its one writer is this
        process: `depthq.lock` holds it for `depthq train`) and write config.json: the training, its
        dataset (absolute path, fingerprint, env config as its manifest records it, the `labeller` of
        the camera labels it learns from) and what a policy of it needs (`PolicyRecord`)."""
        self.out.mkdir(parents=True, exist_ok=True)
        for tmp in self.out.glob(".*.tmp"):
            tmp.unlink(missing_ok=True)
        env = dataset.config.get("env")  # none in a robot's recording
        with dataset.reader(dataset.entries("train")[0]) as reader:
            height, width, _ = reader.image_shape
        if env is None:  # a robot's recording: the default rate, and bins made as the bag import makes them
            from depthq.sim.world import DEFAULT_DECISION_HZ  # MuJoCo: training loads it nowhere else

            rate, bins = DEFAULT_DECISION_HZ, to_dict(BinConfig())
        else:
            rate, bins = env["world"]["decision_hz"], env["bins"]
        config = self.config
        policy = PolicyRecord(float(rate), (height, width), ACTIONS, get_network(config.model).rule, bins)
        where = DatasetRecord(str(dataset.root.resolve()), fingerprint, env, labeller)
        write_record(self.out, to_dict(config), config.head(), config.learning_rate, where, policy, threads)

    def resume(
        self, model: QNet, optimizer: torch.optim.Optimizer, rng: np.random.Generator,
        average: AveragedModel | None = None,
    ) -> TrainState:
        """Restore weights, optimizer, torch RNG, `rng` and `average` (the config's window) from the
        last epoch written; a fresh state if none was."""
        path = self.out / STATE
        if not path.is_file():
            return TrainState()
        tensors, metadata = read_weights(path)
        try:
            meta = json.loads(metadata["state"])
            weights = {k[len("model.") :]: v for k, v in tensors.items() if k.startswith("model.")}
            load_trainable_state(model, weights, path)
            optim_state: dict[int, dict[str, torch.Tensor]] = {}
            for key, value in tensors.items():
                if key.startswith("optim."):
                    _, param, name = key.split(".", 2)
                    optim_state.setdefault(int(param), {})[name] = value
            optimizer.load_state_dict({"state": optim_state, "param_groups": meta["param_groups"]})
            torch.set_rng_state(tensors["rng.torch"])
            rng.bit_generator.state = meta["rng"]
            state = TrainState(int(meta["epoch"]), meta["history"], meta["best"])
        except (KeyError, ValueError, TypeError) as err:
            raise DataError(f"{path}: not a valid resume state ({err})") from err
        _load_average(path, tensors, meta.get("average"), state.epoch, average, self.config.average_from)
        return state

    def write_epoch(
        self,
        model: QNet,
        optimizer: torch.optim.Optimizer,
        rng: np.random.Generator,
        state: TrainState,
        is_best: bool,
        average: AveragedModel | None = None,
        average_loss: tuple[float, float] | None = None,
        seconds: float | None = None,
    ) -> None:
        """Write the epoch `state` ends: resume state first (one file), then the weights (also as
        epoch_NNNN.safetensors at an epoch of `snapshots`; `average`, once it holds an epoch, one per
        epoch up to this one: also average.safetensors, and its validation loss and spread
        `average_loss` in average.json), and metrics.csv, the log of every epoch's metrics and its
        `seconds` (the one timing written: the other files hold none, so a resumed training writes
        them byte for byte as an uninterrupted one)."""
        out = self.out
        weights = trainable_state(model)
        averaged = int(average.n_averaged) if average is not None else 0
        average_from = state.epoch - averaged + 1  # the average holds every epoch since its first
        optim = optimizer.state_dict()
        tensors = {f"model.{k}": v for k, v in weights.items()}
        for param, values in optim["state"].items():
            for key, v in values.items():
                tensors[f"optim.{param}.{key}"] = torch.as_tensor(v).detach().cpu().clone()
        tensors["rng.torch"] = torch.get_rng_state()
        mean = trainable_state(average.module) if averaged else {}
        tensors.update({f"average.{k}": v for k, v in mean.items()})
        meta = {
            "epoch": state.epoch,
            "rng": rng.bit_generator.state,
            "history": state.history,
            "best": state.best,
            "param_groups": optim["param_groups"],
            **({"average": {"from": average_from, "count": averaged}} if averaged else {}),
        }
        atomic_write_bytes(out / STATE, weights_bytes(tensors, {"state": json.dumps(meta)}))
        write_json(out / "last_state.json", meta)
        blob = weights_bytes(weights, {"epoch": str(state.epoch)})
        snapshot = state.epoch in self.config.snapshots
        also = (["best"] if is_best else []) + ([snapshot_stem(state.epoch)] if snapshot else [])
        for stem in ("last", *also):
            atomic_write_bytes(out / f"{stem}.safetensors", blob)
            write_sidecar(out, stem, state.history[-1])
        if averaged:
            atomic_write_bytes(out / "average.safetensors", weights_bytes(mean, {"epoch": str(state.epoch)}))
            val = dict(zip(("val_loss", "val_loss_std"), average_loss, strict=True)) if average_loss else {}
            write_sidecar(out, "average", {"epochs": [average_from, state.epoch], "count": averaged, **val})
        logged = epoch_seconds(out)
        if seconds is not None:
            logged[state.epoch] = seconds
        text = io.StringIO()
        writer = csv.DictWriter(text, fieldnames=METRIC_FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows({**row, "seconds": logged.get(int(row["epoch"]), "")} for row in state.history)
        atomic_write_bytes(out / METRICS, text.getvalue().encode())


def settings_differing(record: dict[str, Any], config: Trained) -> list[str]:
    """The settings in which checkpoint `record` (`read_config`) was trained otherwise than `config`
    asks, but for `epochs`, `data` and `snapshots`; [] for the same training."""
    ignore = {"epochs", "data", "snapshots"}
    old_train = {k: v for k, v in field_paths(record.get("train", {})).items() if k not in ignore}
    new_train = {k: v for k, v in field_paths(to_dict(config)).items() if k not in ignore}
    differing = sorted(k for k in set(old_train) | set(new_train) if old_train.get(k) != new_train.get(k))
    if record.get("learning_rate") != config.learning_rate:  # lr None: a default that may have changed
        differing.append("learning_rate (the default for this model changed)")
    return differing


def epoch_seconds(out: Path) -> dict[int, float]:
    """epoch → the seconds it took, as metrics.csv logged them (none for an epoch it lacks)."""
    try:
        with (out / METRICS).open(newline="") as f:
            rows = list(csv.DictReader(f))
        return {int(row["epoch"]): float(row["seconds"]) for row in rows if row.get("seconds")}
    except (FileNotFoundError, KeyError, ValueError, TypeError):
        return {}


def read_metrics(out: Path) -> dict[str, np.ndarray]:
    """The training folder's metrics.csv as columns, one value per epoch (nan where a cell is empty);
    {} where it has logged no epoch."""
    with (out / METRICS).open(newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) if r[k] else np.nan for r in rows]) for k in rows[0]} if rows else {}


def saved_epoch(out: Path) -> int:
    """Epochs finished in `out`: the epoch of its resume state, 0 if it has none."""
    path = out / STATE
    if not path.is_file():
        return 0
    try:
        with safe_open(path, framework="pt") as f:
            return int(json.loads((f.metadata() or {})["state"])["epoch"])
    except (SafetensorError, OSError, KeyError, ValueError, TypeError) as err:
        raise DataError(f"{path}: not a valid resume state ({err})") from err


def _load_average(
    path: Path, tensors: dict[str, torch.Tensor], saved: dict[str, int] | None, epoch: int,
    average: AveragedModel | None, average_from: int | None,
) -> None:
    """Put a resume state's weight average into `average`, if it is the window asked for."""
    if average is None or average_from is None or epoch < average_from:
        return  # no average asked for, or its window starts after the saved epoch
    if saved is None or saved.get("from") != average_from:
        raise ConfigError(
            f"{path}: resuming at epoch {epoch} inside a weight average from epoch {average_from}, but the "
            f"state holds {'none' if saved is None else 'one from epoch ' + str(saved.get('from'))} "
            "(were the epochs extended inside the window?); train into a new folder"
        )
    try:
        mean = {k[len("average.") :]: v for k, v in tensors.items() if k.startswith("average.")}
        load_trainable_state(average.module, mean, path)
        average.n_averaged.fill_(int(saved["count"]))
    except (KeyError, ValueError, TypeError) as err:
        raise DataError(f"{path}: not a valid resume state ({err})") from err
