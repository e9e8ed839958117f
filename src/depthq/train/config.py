"""Every training hyper-parameter in one frozen dataclass (CleanRL style), stored in each checkpoint."""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

from depthq.blocks.heads import HeadConfig
from depthq.blocks.optim import EPS, RHO, WEIGHT_DECAY
from depthq.blocks.trunk import DEFAULT_TRUNK, INPUT_SIZE, TRUNKS, check_tune_stages
from depthq.checkpoint import WEIGHTS
from depthq.configio import OMIT_DEFAULT, check_choices, check_seed, tagged
from depthq.data.camera_labels import LABEL_SOURCES
from depthq.data.samples import SampleConfig
from depthq.errors import ConfigError
from depthq.flags import CHOICES
from depthq.networks import get_network, network_names

# From docs/convergence.png (200 runs, seed 0, 60 epochs, dropout 0): validation loss at 40 epochs is
# within 8 % of the best of 60 for Depth-Q-Net (0.151 vs 0.139 at 50) and 10 % for Coll-Q-Net (0.058
# vs 0.053); best.safetensors keeps the best epoch. 40 epochs ≈ 80 s per model on 2 CPU cores.
DEFAULT_EPOCHS = 40
# The weights a head form's checkpoint acts with by default (`TrainConfig.weights`): the depth-first
# head's best-validation epoch is a noisy pick of its summed perception and dynamics losses.
DEFAULT_WEIGHTS = {"depth_first": "final"}
# The fraction of the last epochs a head form's training averages by default (`TrainConfig.average`),
# and then acts with: one depth-first Depth-Q-Net's weights two epochs apart drive the hard `val`
# canyons up to 10 m apart, their mean steadily far (docs/design.md#weight-average).
DEFAULT_AVERAGE = {"depth_first": 0.25}
# The forward pass's arithmetic in training and validation (docs/benchmarks.md#precision).
Precision = Literal["fp32", "bf16"]
PRECISIONS: tuple[str, ...] = typing.get_args(Precision)
# The other choice-valued settings' types, each from the tuple or registry that owns its choices: the
# flags list them (`depthq train --help`) and `check_choices` checks them, with no list of them here.
TrunkName = Literal[tuple(TRUNKS)]  # type: ignore[valid-type]
LabelSource = Literal[LABEL_SOURCES]  # type: ignore[valid-type]
Weights = Literal[WEIGHTS]  # type: ignore[valid-type]


def check_precisions(precisions: tuple[str, ...], what: str) -> None:
    """A benchmark's precisions: at least one, each of PRECISIONS (else a ConfigError naming it)."""
    if not precisions:
        raise ConfigError(f"{what} needs at least one precision")
    for precision in precisions:
        if precision not in PRECISIONS:
            raise ConfigError(f"precision must be one of {PRECISIONS}, got {precision!r}")


def network_settings() -> dict[str, type]:
    """Each registered network's own settings class (`Network.Settings`), by its name."""
    return {name: get_network(name).Settings for name in network_names()}


def _int_at_least(name: str, value: object, low: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or value < low:
        raise ConfigError(f"train.{name} must be an integer >= {low}, got {value!r}")


def _positive_float(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not (0 < value < math.inf):
        raise ConfigError(f"train.{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class TrainConfig:
    """One training run: which network, on which data, with which optimizer and schedule.

    An epoch is `train_batches` training batches then `val_batches` validation batches
    (docs/design.md#training).
    `runs` takes the first n usable training runs (the paper's nested subsets); None takes all.
    `lr` None means the network's own rate (`Network.lr`); read the effective one from `learning_rate`.
    Settings whose default depends on other fields (`average`, `weights`; `lr`) are resolved in one
    place, `_resolve_defaults`. The network's own settings are `settings` (`Network.Settings`:
    `--depth.lookahead`), which check their own rules.
    """

    model: str = field(metadata={CHOICES: network_names})  # the network, by its registered name
    data: str  # the dataset folder (depthq collect --out)
    # The first n usable training runs (the paper's nested subsets); none: all of them.
    runs: int | None = None
    # Seeds the head's initialisation and the batches drawn (the same seed, the same weights).
    seed: int = 0
    epochs: int = DEFAULT_EPOCHS  # each of train_batches training then val_batches validation batches
    # Training batches per epoch.
    train_batches: int = 100
    # Validation batches per epoch (the best weights are those of the lowest validation loss).
    val_batches: int = 10
    # Samples per batch.
    batch_size: int = 64
    # Adadelta's learning rate; none: the model's default, 0.1 for both (docs/deviations.md#coll-lr).
    lr: float | None = None
    # Adadelta's decay of its running averages (the original's).
    rho: float = RHO
    # Adadelta's epsilon (the original's).
    eps: float = EPS
    # L2 weight decay of the head's weights (the original's).
    weight_decay: float = WEIGHT_DECAY
    trunk: TrunkName = DEFAULT_TRUNK  # the image network whose feature the head reads (depthq.blocks.trunk)
    # N > 0 trains the trunk's last N of its 7 MBConv stages with the head, from a cache of the frozen
    # early stages' activations per frame (docs/design.md#tuned-trunk; a column or grid trunk); the
    # checkpoint stores those stages. 0: the trunk as it is (frozen: the head alone is trained).
    tune_stages: int = field(default=0, metadata=OMIT_DEFAULT)
    # Dropout on the feature; the paper's 0.5 blurs a frozen feature's predictions
    # (docs/deviations.md#dropout).
    dropout: float = 0.0
    # The action enters the head multiplied by this, so that it weighs against a 1280-d feature
    # (docs/deviations.md#action-scale).
    action_scale: float = 10.0
    # Side of the square image the trunk sees, in pixels.
    input_size: int = INPUT_SIZE
    # P > 0 projects the frozen trunk's feature to P numbers before the head (docs/design.md#heads): a
    # fixed linear map, the top-P principal directions of this training's training features, fitted
    # when it starts. The paper's head took 256 (257 → 4096 with the action), ours 1280: 5× the first
    # layer's arithmetic. 0 (the default until measured on val canyons): no projection.
    feature_projection: int = 0
    # Width of the head's hidden layer (the paper's 4096); its first layer is most of a head step's
    # arithmetic.
    hidden: int = field(default=4096, metadata=OMIT_DEFAULT)
    # Each training sample taken mirrored with probability 1/2 (docs/design.md#mirror): the frame
    # flipped left to right (a second feature cache), the action negated, the depth bins reversed; a
    # canyon's mirror image is a canyon, and a turn's effect on it is the mirrored turn's.
    mirror: bool = field(default=False, metadata=OMIT_DEFAULT)
    # Depth-Q-Net's bins, its targets and a depth_first head's current bins: the LiDAR's ("lidar") or
    # those a labeller estimated from the camera ("camera", written by `depthq label`;
    # docs/design.md#camera-labels). Coll-Q-Net's target is the bump: "lidar" only.
    labels: LabelSource = "lidar"
    # Which frames of the dataset's runs are samples, and their targets (docs/design.md#labels).
    samples: SampleConfig = field(default_factory=SampleConfig)
    # The network's own settings (`Network.Settings`, e.g. Depth-Q-Net's lookahead): flags `--NAME.FIELD`
    # (`--depth.lookahead 3`), stored under the network's name; none: its defaults.
    settings: Any = field(default=None, metadata=tagged("model", network_settings))
    # The weights this checkpoint's policy uses unless told (evaluate --weights): best (lowest
    # validation loss), final (after the last epoch, as the original evaluated them) or average (the
    # last epochs' mean, `average`); none: average when `average` is set, else final for a
    # depth_first head and best for the others. The head form's
    # choice was made on `val` canyons (docs/design.md#weights). Training is the same either way.
    weights: Weights | None = None
    # Epochs whose weights are kept as well (epoch_0040.safetensors, `--weights epoch:40`), so that one
    # long training also gives the policies of shorter ones.
    snapshots: tuple[int, ...] = ()
    # f > 0 also keeps the mean of the weights after each epoch of the training's last fraction f
    # (0.25 of 40 epochs: 31–40; at least the last epoch) as average.safetensors (`--weights
    # average`): stochastic weight averaging's equal-weight mean (torch's `swa_utils.AveragedModel`), a
    # smoother draw of the training's end than one epoch's weights; none: 0.25 for a depth_first head,
    # else 0 (none). Training is the same either way (docs/design.md#weight-average).
    average: float | None = None
    # "bf16": training and validation forward passes under torch.autocast in bfloat16 (weights,
    # gradients, loss and Adadelta stay float32); "fp32": float32 throughout. Policies decide in float32.
    precision: Precision = "fp32"

    def __post_init__(self) -> None:
        check_seed(self.seed)
        if self.model not in network_names():
            raise ConfigError(f"train.model must be one of {network_names()}, got {self.model!r}")
        network = get_network(self.model)
        if self.settings is None:
            object.__setattr__(self, "settings", network.Settings())
        if type(self.settings) is not network.Settings:
            raise ConfigError(f"train.settings of model {self.model!r} must be its "
                              f"{network.Settings.__name__}, got {self.settings!r}")
        if not isinstance(self.data, str) or not self.data:
            raise ConfigError(f"train.data must be a dataset folder, got {self.data!r}")
        if self.runs is not None:
            _int_at_least("runs", self.runs, 1)
        _int_at_least("seed", self.seed, 0)
        for name in ("epochs", "train_batches", "val_batches", "batch_size", "input_size"):
            _int_at_least(name, getattr(self, name), 1)
        if not isinstance(self.samples, SampleConfig):
            raise ConfigError(f"train.samples must be a SampleConfig, got {self.samples!r}")
        if self.lr is not None:
            _positive_float("lr", self.lr)
        _positive_float("eps", self.eps)
        _positive_float("action_scale", self.action_scale)
        for name, low, high in (("rho", 0.0, 1.0), ("dropout", 0.0, 1.0), ("weight_decay", 0.0, math.inf)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value < high:
                raise ConfigError(f"train.{name} must be in [{low}, {high}), got {value!r}")
        check_choices(self, "train")  # trunk, labels, weights, precision
        check_tune_stages(self.trunk, self.tune_stages)
        self._check_projection()
        _int_at_least("hidden", self.hidden, 1)
        network.check_training(self)  # its rules where its own settings meet these
        network.check_head(self.head())  # the head's rules (projection size) and its network's (form)
        self._resolve_defaults()
        if not isinstance(self.mirror, bool):
            raise ConfigError(f"train.mirror must be true or false, got {self.mirror!r}")
        if self.mirror and not TRUNKS[self.trunk].frozen:
            raise ConfigError(f"train.mirror: mirrored samples come from a frozen trunk's feature cache, "
                              f"but trunk {self.trunk!r} is trained with the head")
        self._check_snapshots()
        self._check_average()
        if self.labels not in network.label_sources:
            raise ConfigError(
                f"train.labels {self.labels!r}: {network.title} learns only from labels "
                f"{network.label_sources}; use --labels {network.label_sources[0]}"
            )

    def _resolve_defaults(self) -> None:
        """The defaults that depend on other fields, all resolved here (once the head is known), so that
        a stored config names its choice:

        - `average` none: its head form's (`DEFAULT_AVERAGE`: 0.25 for depth_first), else 0;
        - `weights` none: average when the training averages, else its head form's
          (`DEFAULT_WEIGHTS`: final for depth_first), else best.

        `lr` none is the one left unresolved: configs have always stored it as none (model folders
        are matched on it), and `learning_rate` reads the network's rate (`Network.lr`)."""
        form = self.head().form
        if self.average is None:
            object.__setattr__(self, "average", DEFAULT_AVERAGE.get(form, 0.0))
        if self.weights is None:
            chosen = "average" if self.average else DEFAULT_WEIGHTS.get(form, "best")
            object.__setattr__(self, "weights", chosen)

    def _check_projection(self) -> None:
        _int_at_least("feature_projection", self.feature_projection, 0)
        p, trunk = self.feature_projection, TRUNKS[self.trunk]
        if p and self.tune_stages:
            raise ConfigError(f"train.feature_projection {p}: the projection is fitted to a frozen trunk's "
                              f"features, but tune_stages {self.tune_stages} trains the trunk; use 0")
        if p and not trunk.frozen:
            raise ConfigError(
                f"train.feature_projection {p}: only a frozen trunk's cached features are projected, but "
                f"trunk {self.trunk!r} is trained with the head; use 0"
            )
        if p > trunk.feature_dim:
            raise ConfigError(
                f"train.feature_projection must be in 1..{trunk.feature_dim} (trunk {self.trunk!r}'s "
                f"feature size) or 0, got {p}"
            )

    def head(self) -> HeadConfig:
        """The head this training builds: its network's (`Network.head_config`) of these settings."""
        paper = HeadConfig(self.model, TRUNKS[self.trunk].feature_dim, hidden=self.hidden,
                           dropout=self.dropout, action_scale=self.action_scale, lookahead=1,
                           feature_projection=self.feature_projection, form="concat", output_bias=0.0,
                           bin_gradient="relu")
        return get_network(self.model).head_config(paper, self.settings)

    def _check_snapshots(self) -> None:
        if not isinstance(self.snapshots, tuple):
            raise ConfigError(f"train.snapshots must be a tuple of epochs, got {self.snapshots!r}")
        for epoch in self.snapshots:
            if isinstance(epoch, bool) or not isinstance(epoch, int) or not 1 <= epoch <= self.epochs:
                raise ConfigError(
                    f"train.snapshots: epoch {epoch!r} is not one of this training's epochs 1..{self.epochs}"
                )
        repeated = sorted({e for e in self.snapshots if self.snapshots.count(e) > 1})
        if repeated:
            raise ConfigError(f"train.snapshots repeats epoch(s) {repeated}: {self.snapshots}")

    def _check_average(self) -> None:
        f = self.average
        if isinstance(f, bool) or not isinstance(f, int | float) or not 0 <= f <= 1:
            raise ConfigError(f"train.average must be a fraction of the epochs in [0, 1] (0: none), "
                              f"got {f!r}")
        if self.weights == "average" and not f:
            raise ConfigError("train.weights 'average' needs a weight average: set train.average > 0")

    @property
    def average_from(self) -> int | None:
        """The first epoch whose weights enter the average; None without one."""
        return self.epochs - max(1, math.ceil(self.average * self.epochs)) + 1 if self.average else None

    @property
    def learning_rate(self) -> float:
        """The learning rate in use: `lr`, or the network's own (`Network.lr`)."""
        return get_network(self.model).lr if self.lr is None else float(self.lr)
