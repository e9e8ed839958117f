"""What a network is: one class per network, registered by name (`depthq.networks.registry`), owning
everything that differs between networks, so that the trainer, the policies, evaluation, export, the
report and the sweeps ask it rather than test its name.

A `Network` says what it is called (`name`, as checkpoints, sweeps and folders record it; `title`;
`label`, the report's short name; `colour`), which settings are its own (`Settings`: a frozen
dataclass, a training's `TrainConfig.settings`, spelled `--NAME.FIELD` and stored under its name), how
it trains (`lr`, its default learning rate; the target its samples learn, `target`, and the samples
themselves, `samples`; its head, `head_config` and `build_head`; its loss, `loss_function`; the
head's own training loss is the head's: `depthq.blocks.heads.Head.training_loss`), how it is measured offline
(`metric`), how it acts (its own acting settings, `Acting`: a frozen dataclass, an evaluation's
`EvalConfig.acting`, spelled `--NAME.FIELD` and stored under its name in a summary; `candidates`: what
a frame's values are predicted for; `output`: a head's raw output of one frame's candidates → its
values; `scores`: values → one score per candidate, `maximise`: whether the highest wins; `tie_tol`;
`rule`, by the name a checkpoint records), what an exported graph outputs (`onnx_output`), and how its values
are drawn (`plot`). Subclasses set the class attributes and override what differs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Generic, Literal, Protocol, TypeVar

import numpy as np
import torch

from depthq.blocks.heads import Head, HeadConfig
from depthq.blocks.losses import LossFn
from depthq.control.action_selection import candidate_sequences, first_actions, pick_best
from depthq.data.camera_labels import LABEL_SOURCES
from depthq.data.manifest import Dataset
from depthq.data.samples import SampleConfig, Target
from depthq.data.views import view_arrays
from depthq.errors import ConfigError

S = TypeVar("S")  # a network's own settings (`Network.Settings`)


@dataclass(frozen=True)
class NoSettings:
    """The (training or acting) settings of a network that has none of its own."""


class Training(Protocol):
    """What a network reads of a training's config: `depthq.train.config.TrainConfig` (a layer above
    this one) has these, and its own settings in `settings` (`Network.Settings`)."""

    model: str
    trunk: str
    tune_stages: int
    labels: str
    samples: SampleConfig
    settings: Any


@dataclass(frozen=True)
class ValuePlot:
    """How a policy's per-candidate values are drawn (Fig. 4, its video): "bins", each action's
    predicted depth bins over the true depth that followed; "bars", one bar per action."""

    style: Literal["bins", "bars"]
    label: str  # the value axis
    limits: tuple[float, float]


class Network(Generic[S]):
    """One network: its names, its own settings, its training, its offline metric, its rule and how it
    is drawn."""

    name: ClassVar[str]  # the name checkpoints (head.kind, train.model), sweeps and model folders record
    title: ClassVar[str]  # e.g. "Depth-Q-Net"
    label: ClassVar[str]  # the report's short name, e.g. "DQN"
    colour: ClassVar[str]  # the report's line colour (matplotlib)
    lr: ClassVar[float]  # the learning rate `TrainConfig.lr` none means
    # Its own training settings, a frozen dataclass whose defaults are its defaults (`TrainConfig.settings`;
    # a sweep's setting of another network's is not one of its settings: `--set depth.lookahead=1,3`
    # trains each Coll-Q-Net once).
    Settings: ClassVar[type] = NoSettings
    target: ClassVar[Target]  # what its samples learn from a run (`depthq.data.samples.Target`)
    label_sources: ClassVar[tuple[str, ...]] = LABEL_SOURCES  # `TrainConfig.labels` it can learn from
    # Whether its outputs are depth bins behind a ReLU, outputs that can die (`depthq.train.dead_outputs`).
    outputs_bins: ClassVar[bool] = False
    metric: ClassVar[str]  # the offline metric's name (its training loss on every validation sample)
    metric_title: ClassVar[str]  # that metric in Table I's column, e.g. "abs diff"
    loss_title: ClassVar[str]  # its loss in Fig. 5's title, e.g. "cross-entropy"
    rule: ClassVar[str]  # its selection rule, by the name a checkpoint records
    rule_text: ClassVar[str]  # that rule in words, as an exported graph carries it
    maximise: ClassVar[bool]  # whether the highest score wins (else the lowest)
    tie_tol: ClassVar[float]  # scores within this of the best are tied (`pick_best`)
    # Its own acting settings, a frozen dataclass whose defaults are its defaults (an evaluation's
    # `EvalConfig.acting` holds every network's that has some, by name: which network an evaluation drives
    # is known only from its checkpoint).
    Acting: ClassVar[type] = NoSettings
    # Whether its predicted scores are on its oracle's true scores' scale, so that their difference
    # measures its error (Depth-Q-Net's metres; not Coll-Q-Net's probabilities against 0 or 1 bumps).
    comparable_scores: ClassVar[bool] = False
    decisive: ClassVar[float]  # an oracle of it decides a step when its candidates' scores differ by more
    onnx_output: ClassVar[str]  # the exported graph's output name
    plot: ClassVar[ValuePlot]
    featured: ClassVar[bool] = False  # the report's Fig. 4 and video show this network's best model
    # The paper's Table I for it: training runs → (mean distance m, successes of 20); {}: not in the paper.
    paper: ClassVar[dict[int, tuple[float, float]]] = {}

    def __repr__(self) -> str:
        return f"<network {self.name!r}: {self.title}>"

    # -- training --------------------------------------------------------------------------------
    def check_training(self, config: Training) -> None:
        """Its rules for a training's settings where its own meet the general ones (e.g. a lookahead
        against the runs' length); its settings' own rules are checked by `Settings` itself."""

    def head_config(self, head: HeadConfig, settings: S) -> HeadConfig:
        """Its head of `settings`, from a training's `head`: by default the paper's head as it is (one
        step, "concat", the bins' settings at their neutral values)."""
        return head

    def check_head(self, config: HeadConfig) -> None:
        """Its own rules for a head (the shape's are `HeadConfig`'s): by default the paper's head of one
        step."""
        if config.lookahead != 1:
            raise ConfigError(f"HeadConfig.lookahead: {self.title} predicts one step, so its lookahead "
                              f"must be 1, got {config.lookahead!r}")
        if config.form != "concat":
            raise ConfigError(f"HeadConfig.form {config.form!r}: {self.title} has only 'concat'")
        if config.output_bias:
            raise ConfigError(f"HeadConfig.output_bias {config.output_bias}: a Depth-Q-Net's (its outputs "
                              f"are depth bins), not {self.title}'s")
        if config.bin_gradient != "relu":
            raise ConfigError(f"HeadConfig.bin_gradient {config.bin_gradient!r}: a Depth-Q-Net's (its "
                              f"outputs are depth bins), not {self.title}'s")

    def build_head(self, config: HeadConfig) -> Head:
        """Its head of `config` (checked by `check_head`)."""
        raise NotImplementedError

    def samples(
        self, dataset: Dataset, split: str, n_runs: int | None, config: Training, labels: str | None = None
    ) -> dict[str, np.ndarray]:
        """Its samples of `split` (the first `n_runs` usable runs; None: all) as `view_arrays` gives
        them for its `target`; `labels` (None: the config's) where the bins come from."""
        return view_arrays(dataset, split, n_runs, type(self).target, config.samples, 1,
                           config.labels if labels is None else labels)

    def check_targets(self, targets: np.ndarray, where: str) -> None:
        """Its training samples' targets can teach it (`where`: the runs they came from, in words)."""

    def loss_function(self, settings: S) -> LossFn:
        """Its training loss: (outputs, targets) → (batch loss, per-sample loss (B,))."""
        raise NotImplementedError

    def step_loss(self, settings: S) -> LossFn:
        """The loss of one predicted step (a multi-step head's offline metric measures each step by it)."""
        return self.loss_function(settings)

    def bootstrap(self, settings: S) -> float:
        """γ > 0: it learns a bootstrapped target (`depthq.train.bootstrap`); 0: its own target alone."""
        return 0.0

    # -- acting ----------------------------------------------------------------------------------
    def own_acting(self, acting: Mapping[str, Any] | None) -> Any:
        """Its acting settings among an evaluation's (`EvalConfig.acting`, by network name; None: none
        given): its own there, else its defaults."""
        own = (acting or {}).get(self.name)
        return self.Acting() if own is None else own

    def candidates(self, actions: np.ndarray, lookahead: int, acting: Any) -> np.ndarray:
        """What one frame's values are predicted for: the candidate `actions` (N,), or for a head that
        looks `lookahead` steps ahead each held for them (N, K)."""
        actions = np.asarray(actions, np.float64)
        return actions if lookahead == 1 else candidate_sequences(actions, lookahead)

    def output(self, raw: torch.Tensor) -> torch.Tensor:
        """One frame's candidates' raw head outputs → their values (what a policy and a graph give)."""
        return raw

    def outputs(self, raw: torch.Tensor) -> torch.Tensor:
        """`output` of F frames' raw outputs (F, N, …) at once: the same values."""
        return raw

    def scores(self, values: np.ndarray, acting: Any = None) -> np.ndarray:
        """One frame's values → one score per candidate (the best wins: `maximise`), by its acting
        settings (None: its defaults)."""
        return np.asarray(values, np.float64)

    def choose(self, values: np.ndarray, candidates: np.ndarray, acting: Any = None) -> float:
        """The action one frame's values select: the best-scoring candidate's first action, ties
        within `tie_tol` going straight if straight is tied, else to the first."""
        scores = self.scores(values, acting)
        return pick_best(scores, first_actions(candidates), self.maximise, self.tie_tol)

    def true_scores(self, bins: np.ndarray, bumped: np.ndarray, acting: Any) -> np.ndarray:
        """An oracle of it (`depthq.evaluate.oracle`): each candidate's score from its true bins
        (N, K, bins) and whether it bumps (N,)."""
        raise ConfigError(f"{self.title} has no oracle")
