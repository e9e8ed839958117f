"""The training loop (docs/design.md#training): epochs of `train_batches` Adadelta steps on batches
drawn "a random run, then a random frame of it", then `val_batches` fixed validation batches; a
checkpoint every epoch.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from torch.optim import Optimizer
from torch.optim.swa_utils import AveragedModel
from torch.utils.tensorboard import SummaryWriter

from depthq.blocks.device import resolve_device
from depthq.blocks.heads import Head, QNet
from depthq.blocks.losses import LossFn
from depthq.blocks.optim import make_optimizer
from depthq.blocks.trunk import TRUNKS
from depthq.checkpoint import TrainingCheckpoint, TrainState
from depthq.data.manifest import Dataset
from depthq.data.views import FrameView
from depthq.errors import ConfigError
from depthq.networks import build_qnet, get_network
from depthq.parallel import cores
from depthq.progress import Bar
from depthq.train.bootstrap import bootstrapped_targets
from depthq.train.config import TrainConfig
from depthq.train.features import load_activations, load_features
from depthq.train.samples import ActivationSamples, Batch, FeatureSamples, ImageSamples, Samples


class DivergedError(ConfigError):
    """The loss became NaN or infinite; the usual cause is a learning rate too large (CLI exit 2)."""


def train(
    config: TrainConfig, out: Path, progress: bool = True, device: str = "auto", threads: int | None = None
) -> Path:
    """Train `config` into the checkpoint folder `out` (`depthq.checkpoint.training`, written once per
    epoch) and return it.

    A folder holding this training resumes from its last epoch, bit for bit as if never stopped (on
    the CPU, with the same `threads`: torch sums floats in an order that depends on their number;
    None: this process's cores; a GPU's kernels need not be deterministic); a finished one is
    returned as is; one holding another training is a ConfigError. `device`: see `depthq.blocks.device`.
    """
    out = Path(out)
    where = resolve_device(device)
    dataset = Dataset.open(Path(config.data))
    dataset.check_idle()  # not while `depthq label` rewrites its runs
    labeller = dataset.labeller() if config.labels == "camera" else None  # one, or refused
    fingerprint = dataset.fingerprint()
    checkpoint = TrainingCheckpoint.open(out, config, fingerprint)  # refused before anything is read
    if checkpoint.epochs_done >= config.epochs:
        return out
    train_set, val_set = _samples(config, dataset, progress, where)
    torch.set_num_threads(threads or cores())
    checkpoint.start(dataset, fingerprint, torch.get_num_threads(), labeller)
    # Adadelta's running averages of tiny gradients reach subnormal floats, which x86 CPUs process
    # ~100× slower: flushed to zero, a head step is 20 ms instead of seconds (a process-wide setting).
    torch.set_flush_denormal(True)
    torch.manual_seed(config.seed)  # head initialisation and dropout
    model = build_qnet(config.head(), config.trunk, config.tune_stages).to(where)
    c = config
    optimizer = make_optimizer(model, c.learning_rate, c.weight_decay, c.rho, c.eps)
    loss_fn = loss_function(config)
    gamma = get_network(config.model).bootstrap(config.settings)  # γ > 0: a bootstrapped target
    rng = np.random.default_rng(config.seed)  # training batches
    val_rng = np.random.default_rng([config.seed, 1])  # the same validation batches every epoch
    val_batches = val_set.draw(config.val_batches * config.batch_size, val_rng).split(config.batch_size)
    # The weight average (`TrainConfig.average`); buffers too, so a trained trunk's BatchNorm statistics
    # are those of the averaged epochs.
    average = AveragedModel(model, use_buffers=True) if config.average else None
    state = checkpoint.resume(model, optimizer, rng, average)
    if config.feature_projection and not state.epoch:  # a resumed training's is in its checkpoint
        # On the training samples' cached features (a frozen trunk's: TrainConfig allows no other),
        # never the validation split's.
        model.head.fit_projection(train_set.features[0].numpy())

    target_head = None  # a bootstrapped target's network Q̄: the previous epoch's head, from epoch 2 on
    tb = SummaryWriter(out / "tb", purge_step=state.epoch + 1)
    bar = Bar(total=config.epochs, initial=state.epoch, desc=f"train {config.model}", unit="epoch",
               disable=not progress)
    try:
        for epoch in range(state.epoch + 1, config.epochs + 1):
            start = time.perf_counter()
            if gamma and epoch > 1:
                target_head = copy.deepcopy(model.head).eval()
            model.train()
            train_losses = []
            for _ in range(config.train_batches):
                batch = train_set.batch(train_set.draw(config.batch_size, rng)).to(where)
                batch = with_target(batch, target_head, gamma)
                train_losses.append(train_step(model, train_set, batch, loss_fn, optimizer, config.precision))
                _check_finite(train_losses[-1], "training", epoch, out, state)

            val_loss, val_loss_std = validate(model, val_set, val_batches, loss_fn, target_head, gamma,
                                              config.precision)
            row = {
                "epoch": epoch,
                "train_loss": float(np.mean(train_losses)),
                "val_loss": val_loss,
                "val_loss_std": val_loss_std,  # the paper's over-fitting signal (Fig. 5)
            }
            _check_finite(row["val_loss"], "validation", epoch, out, state)
            is_best = state.best is None or row["val_loss"] < state.best["val_loss"]
            state = TrainState(epoch, [*state.history, row], row if is_best else state.best)
            average_loss = None
            if average is not None and epoch >= config.average_from:
                average.update_parameters(model)
                average_loss = validate(average.module, val_set, val_batches, loss_fn, target_head, gamma,
                                        config.precision)
            checkpoint.write_epoch(model, optimizer, rng, state, is_best, average, average_loss,
                                   seconds=round(time.perf_counter() - start, 3))
            for key in ("train_loss", "val_loss", "val_loss_std"):
                tb.add_scalar(f"loss/{key}", row[key], epoch)
            bar.set_postfix(train=f"{row['train_loss']:.4f}", val=f"{row['val_loss']:.4f}")
            bar.update()
    finally:
        bar.close()
        tb.close()
    return out


def validate(
    model: QNet, val_set: Samples, val_batches: tuple[torch.Tensor, ...], loss_fn: LossFn,
    target_head: Head | None, gamma: float = 0.0, precision: str = "fp32",
) -> tuple[float, float]:
    """The mean validation loss of `model` over the fixed validation batches, and its mean per-batch
    standard deviation over the samples; in eval mode (no dropout; a trained trunk's BatchNorm uses
    its running statistics). `gamma`: a bootstrapped target's (`with_target`)."""
    model.eval()
    where = next(model.parameters()).device
    losses, stds = [], []
    with torch.no_grad():
        for idx in val_batches:
            batch = with_target(val_set.batch(idx).to(where), target_head, gamma)
            loss, per_sample = loss_fn(predict(model, val_set, batch, precision), batch.targets)
            losses.append(loss.item())
            stds.append(per_sample.std().item())
    return float(np.mean(losses)), float(np.mean(stds))


def loss_function(config: TrainConfig) -> LossFn:
    """The training loss of `config`'s network (`Network.loss_function` of its own settings)."""
    return get_network(config.model).loss_function(config.settings)


def with_target(batch: Batch, target_head: Head | None, gamma: float) -> Batch:
    """`batch` with its bootstrapped targets (`depthq.train.bootstrap`) once a target network exists."""
    if target_head is None:
        return batch
    targets = bootstrapped_targets(batch.targets, target_head, batch.next_inputs, gamma)
    return replace(batch, targets=targets)


def predict(model: QNet, samples: Samples, batch: Batch, precision: str = "fp32") -> torch.Tensor:
    """The model's float32 outputs for `batch`; "bf16" runs the forward pass under bfloat16 autocast, and
    the loss is then taken of its outputs in float32 (elementwise ops in bf16 would round the loss)."""
    bf16 = precision == "bf16"
    with torch.autocast(device_type=batch.inputs.device.type, dtype=torch.bfloat16, enabled=bf16):
        return samples.predict(model, batch).float()


def train_step(
    model: QNet, samples: Samples, batch: Batch, loss_fn: LossFn, optimizer: Optimizer,
    precision: str = "fp32",
) -> float:
    """One Adadelta step on `batch` (`predict`'s `precision`); returns its loss. A non-finite loss is
    returned without a step. The head says what it fits and its loss (`Head.training_outputs`,
    `Head.training_loss`: a "depth_first" head fits each part to its own target)."""
    head, bf16 = model.head, precision == "bf16"
    with torch.autocast(device_type=batch.inputs.device.type, dtype=torch.bfloat16, enabled=bf16):
        features = samples.trunk_features(model, batch)
        outputs = tuple(out.float() for out in head.training_outputs(features, batch.actions, batch.current))
    loss = head.training_loss(outputs, batch.targets, batch.current, loss_fn)
    value = loss.item()
    if math.isfinite(value):
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    return value


def _samples(
    config: TrainConfig, dataset: Dataset, progress: bool, device: torch.device
) -> tuple[Samples, Samples]:
    """Training and validation samples: cached features for a frozen trunk, cached activations of its
    frozen stages for a tuned one, decoded images otherwise."""
    network = get_network(config.model)
    arrays = {split: network.samples(dataset, split, n, config)
              for split, n in (("train", config.runs), ("val", None))}
    network.check_targets(arrays["train"]["target"],
                          f"the selected training runs of {config.data} (runs={config.runs or 'all'})")
    if config.tune_stages:
        n, size = config.tune_stages, config.input_size
        table = load_activations(dataset, n, size, progress, device)
        mirrored = (load_activations(dataset, n, size, progress, device, mirrored=True)
                    if config.mirror else None)
        return (ActivationSamples(arrays["train"], table, "train", mirrored=mirrored),
                ActivationSamples(arrays["val"], table, "val"))
    if TRUNKS[config.trunk].frozen:
        table = load_features(dataset, config.trunk, config.input_size, progress, device)
        mirrored = (load_features(dataset, config.trunk, config.input_size, progress, device, mirrored=True)
                    if config.mirror else None)
        following = network.bootstrap(config.settings) > 0  # validation is never mirrored: as recorded
        return (FeatureSamples(arrays["train"], table, "train", following, mirrored),
                FeatureSamples(arrays["val"], table, "val", following))
    if progress:
        Bar.write(f"trunk {config.trunk!r} is trained with the head, on images")
    return (ImageSamples(FrameView(dataset, "train", arrays["train"]), config.input_size, progress),
            ImageSamples(FrameView(dataset, "val", arrays["val"]), config.input_size, progress))


def _check_finite(loss: float, phase: str, epoch: int, out: Path, state: TrainState) -> None:
    if not math.isfinite(loss):
        kept = (f"the last good checkpoint (epoch {state.epoch}) is kept in {out}" if state.epoch
                else f"no epoch finished, so {out} holds no weights")
        raise DivergedError(
            f"training diverged: {phase} loss is {loss} in epoch {epoch}; stopped, {kept}. "
            "Lower the learning rate (--lr) and train into a new folder"
        )
