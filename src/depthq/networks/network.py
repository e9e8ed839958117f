"""What a network is: one class per network, registered by name (`depthq.networks.registry`), owning
everything that differs between networks, so that the trainer, the policies, evaluation, export, the
report and the sweeps ask it rather than test its name.

A `Network` says what it is called (`name`, as checkpoints, sweeps and folders record it; `title`;
`label`, the report's short name; `colour`), how it trains (`lr`, its default learning rate; the data
view its samples come from, `samples`; its head, `build_head`; its loss, `loss_function`; the head's
own training loss is the head's: `depthq.blocks.heads.Head.training_loss`), how it is measured offline
(`metric`), how it acts (`output`: a head's raw output of one frame's candidates → its values;
`scores`: values → one score per candidate, `maximise`: whether the highest wins; `tie_tol`; `rule`,
by the name a checkpoint records), what an exported graph outputs (`onnx_output`), and how its values
are drawn (`plot`). Subclasses set the class attributes and override what differs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
import torch

from depthq.blocks.heads import Head, HeadConfig
from depthq.blocks.losses import LossFn
from depthq.control.action_selection import Selection, first_actions, pick_best
from depthq.data.camera_labels import LABEL_SOURCES
from depthq.data.manifest import Dataset
from depthq.data.views import view_arrays
from depthq.errors import ConfigError


@dataclass(frozen=True)
class ValuePlot:
    """How a policy's per-candidate values are drawn (Fig. 4, its video): "bins", each action's
    predicted depth bins over the true depth that followed; "bars", one bar per action."""

    style: Literal["bins", "bars"]
    label: str  # the value axis
    limits: tuple[float, float]


class Network:
    """One network: its names, its training, its offline metric, its rule and how it is drawn.

    `config` arguments are a `depthq.train.config.TrainConfig` (a layer above this one)."""

    name: ClassVar[str]  # the name checkpoints (head.kind, train.model), sweeps and model folders record
    title: ClassVar[str]  # e.g. "Depth-Q-Net"
    label: ClassVar[str]  # the report's short name, e.g. "DQN"
    colour: ClassVar[str]  # the report's line colour (matplotlib)
    lr: ClassVar[float]  # the learning rate `TrainConfig.lr` none means
    view: ClassVar[str]  # the data view its samples come from (`depthq.data.samples.TARGETS`)
    label_sources: ClassVar[tuple[str, ...]] = LABEL_SOURCES  # `TrainConfig.labels` it can learn from
    looks_ahead: ClassVar[bool] = False  # whether it predicts `TrainConfig.lookahead` > 1 steps
    bootstraps: ClassVar[bool] = False  # whether it takes a bootstrapped target (`TrainConfig.bootstrap`)
    # TrainConfig settings it has no use for: a sweep's variant that sets them trains it once.
    unused_settings: ClassVar[tuple[str, ...]] = ()
    metric: ClassVar[str]  # the offline metric's name (its training loss on every validation sample)
    metric_title: ClassVar[str]  # that metric in Table I's column, e.g. "abs diff"
    loss_title: ClassVar[str]  # its loss in Fig. 5's title, e.g. "cross-entropy"
    rule: ClassVar[str]  # its selection rule, by the name a checkpoint records
    rule_text: ClassVar[str]  # that rule in words, as an exported graph carries it
    maximise: ClassVar[bool]  # whether the highest score wins (else the lowest)
    tie_tol: ClassVar[float]  # scores within this of the best are tied (`pick_best`)
    uses_selection: ClassVar[bool] = False  # whether `Selection` (a depth rule) scores its values
    decisive: ClassVar[float]  # an oracle of it decides a step when its candidates' scores differ by more
    onnx_output: ClassVar[str]  # the exported graph's output name
    plot: ClassVar[ValuePlot]
    featured: ClassVar[bool] = False  # the report's Fig. 4 and video show this network's best model
    # The paper's Table I for it: training runs → (mean distance m, successes of 20); {}: not in the paper.
    paper: ClassVar[dict[int, tuple[float, float]]] = {}

    def __repr__(self) -> str:
        return f"<network {self.name!r}: {self.title}>"

    # -- training --------------------------------------------------------------------------------
    def default_form(self, lookahead: int) -> str:
        """The head form (`depthq.blocks.heads.HEAD_FORMS`) it gets unless told."""
        return "concat"

    def check_lookahead(self, lookahead: object, what: str = "lookahead") -> None:
        """Its lookahead: an integer >= 1, and 1 unless it `looks_ahead` (else a ConfigError naming
        `what`)."""
        if isinstance(lookahead, bool) or not isinstance(lookahead, int) or lookahead < 1:
            raise ConfigError(f"{what} must be an integer >= 1, got {lookahead!r}")
        if lookahead != 1 and not self.looks_ahead:
            raise ConfigError(f"{what} is a lookahead net's; {self.title} predicts one step, so its "
                              f"lookahead must be 1, got {lookahead!r}")

    def check_head(self, config: HeadConfig) -> None:
        """Its own rules for a head (the shape's are `HeadConfig`'s): by default the paper's head."""
        self.check_lookahead(config.lookahead, "HeadConfig.lookahead")
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
        self, dataset: Dataset, split: str, n_runs: int | None, config: Any, labels: str | None = None
    ) -> dict[str, np.ndarray]:
        """Its samples of `split` (the first `n_runs` usable runs; None: all) as `view_arrays` gives
        them, `target` what it learns; `labels` (None: the config's) where the bins come from."""
        return view_arrays(dataset, split, n_runs, self.view, config.samples, config.lookahead,
                           config.labels if labels is None else labels)

    def loss_function(self, config: Any) -> LossFn:
        """Its training loss: (outputs, targets) → (batch loss, per-sample loss (B,))."""
        raise NotImplementedError

    # -- acting ----------------------------------------------------------------------------------
    def output(self, raw: torch.Tensor) -> torch.Tensor:
        """One frame's candidates' raw head outputs → their values (what a policy and a graph give)."""
        return raw

    def outputs(self, raw: torch.Tensor) -> torch.Tensor:
        """`output` of F frames' raw outputs (F, N, …) at once: the same values."""
        return raw

    def scores(self, values: np.ndarray, selection: Selection | None = None) -> np.ndarray:
        """One frame's values → one score per candidate (the best wins: `maximise`)."""
        return np.asarray(values, np.float64)

    def choose(self, values: np.ndarray, candidates: np.ndarray, selection: Selection | None = None) -> float:
        """The action one frame's values select: the best-scoring candidate's first action, ties
        within `tie_tol` going straight if straight is tied, else to the first."""
        scores = self.scores(values, selection)
        return pick_best(scores, first_actions(candidates), self.maximise, self.tie_tol)

    def true_scores(self, bins: np.ndarray, bumped: np.ndarray, selection: Selection) -> np.ndarray:
        """An oracle of it (`depthq.evaluate.oracle`): each candidate's score from its true bins
        (N, K, bins) and whether it bumps (N,)."""
        raise ConfigError(f"{self.title} has no oracle")
