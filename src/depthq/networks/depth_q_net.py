"""Depth-Q-Net (docs/design.md#heads): predicts, for each candidate action, the depth bins one step
later (or K steps: docs/design.md#lookahead), and acts on the action whose nearest predicted obstacle
is farthest (docs/design.md#action-selection). Its own training settings are `DepthSettings`
(`--depth.lookahead`, ...), its acting settings `Selection` (`--depth.rule`, ...)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from typing import ClassVar, Literal

import numpy as np
import torch

from depthq.blocks.heads import BIN_GRADIENTS, HEAD_FORMS, DepthFirstHead, DepthHead, Head, HeadConfig
from depthq.blocks.losses import DEPTH_LOSSES, LossFn, depth_l1_loss, lookahead_l1_loss
from depthq.blocks.trunk import TRUNKS
from depthq.configio import OMIT_DEFAULT, check_choices
from depthq.control.action_selection import DEPTH_RULES, RULES, candidate_sequences, sequence_scores
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target
from depthq.data.views import view_arrays
from depthq.errors import ConfigError
from depthq.networks.network import Network, Training, ValuePlot
from depthq.networks.registry import register_network

# A one-step Depth-Q-Net's default head form (docs/oracle_gap.md#depth-first: it drives the hard `val`
# canyons twice as far as "concat"); a Depth-Q-Net looking further ahead knows only "concat".
DEFAULT_FORM = "depth_first"
DepthLoss = Literal[DEPTH_LOSSES]  # type: ignore[valid-type]
HeadForm = Literal[HEAD_FORMS]  # type: ignore[valid-type]
BinGradient = Literal[BIN_GRADIENTS]  # type: ignore[valid-type]
DepthRule = Literal[DEPTH_RULES]  # type: ignore[valid-type]


@dataclass(frozen=True)
class DepthSettings:
    """Depth-Q-Net's own training settings (`TrainConfig.settings` of a Depth-Q-Net: `--depth.*`, stored
    as "depth" in a checkpoint's train record). `head_form` none is resolved here: depth_first for a
    one-step net, else concat."""

    # Its L1 loss over the bins (`depthq.blocks.losses.depth_l1_loss`)
    depth_loss: DepthLoss = "original"
    # Its lookahead K (docs/design.md#lookahead): the depth bins at t+1 … t+K predicted from the K actions
    # taken; 1 is the paper's one-step net. Not `samples.horizon`, which is Coll-Q-Net's collision-target
    # window (5 frames) and also sets which samples Depth-Q-Net drops: the two are separate settings (a
    # lookahead of 3 with the original's targets keeps horizon 5).
    lookahead: int = 1
    # Weight of lookahead step k in the loss: lookahead_discount ** (k − 1). 1 weighs every step alike
    # (each is a measured frame, and the selection rule's minimum over the steps needs them all).
    lookahead_discount: float = 1.0
    # The head's form: depth_first (the current bins read from the feature, then the next bins from
    # them and the action), concat (the action appended to the feature: the paper's head) or
    # per_action (bins per anchor action); none: depth_first for a one-step net, else concat (a net
    # looking further ahead has only "concat"; docs/design.md#heads).
    head_form: HeadForm | None = None
    # The initial bias of its layers that output depth bins, in metres (the paper's: 0). Above 0, an
    # output unit behind the final ReLU starts alive for every input, so none is dead (always 0, no
    # reading to the policy) from the initialisation on (docs/oracle_gap.md#dead-bins).
    output_bias: float = field(default=0.0, metadata=OMIT_DEFAULT)
    # What its output ReLU passes back in training (docs/design.md#dead-outputs): "relu" its own gradient
    # (none below 0: a bin below 0 for every input stays 0, a dead output, no reading to the policy),
    # "straight_through" the gradient as if there were no ReLU, so a bin below 0 where its target is
    # near is pulled up. The values, and so acting, are the ReLU's either way.
    bin_gradient: BinGradient = field(default="relu", metadata=OMIT_DEFAULT)
    # γ > 0 trains it on a bootstrapped value instead of the next frame's bins alone
    # (docs/design.md#bootstrap): per bin (1 − γ)·d_{t+1} + γ·min(d_{t+1}, Q̄(s_{t+1}, a*)), a* the
    # greedy action of the previous epoch's network Q̄ at the next frame: the nearest depth along the
    # greedy policy's future, discounted (a safety Bellman equation). 0: the paper's one-step target.
    bootstrap: float = field(default=0.0, metadata=OMIT_DEFAULT)

    def __post_init__(self) -> None:
        k = self.lookahead
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ConfigError(f"depth.lookahead must be an integer >= 1, got {k!r}")
        if self.head_form is None:
            object.__setattr__(self, "head_form", DEFAULT_FORM if k == 1 else "concat")
        check_choices(self, "depth")  # depth_loss, head_form, bin_gradient
        discount = self.lookahead_discount
        if isinstance(discount, bool) or not isinstance(discount, int | float) or not 0 < discount <= 1:
            raise ConfigError(f"depth.lookahead_discount must be in (0, 1], got {discount!r}")
        if self.head_form != "concat" and k != 1:
            raise ConfigError(f"depth.head_form {self.head_form!r} is a one-step Depth-Q-Net's (lookahead "
                              f"1), got lookahead {k!r}")
        bias = self.output_bias
        if isinstance(bias, bool) or not isinstance(bias, int | float) or not 0 <= bias < float("inf"):
            raise ConfigError(f"depth.output_bias must be a finite number >= 0, got {bias!r}")
        g = self.bootstrap
        if isinstance(g, bool) or not isinstance(g, int | float) or not 0 <= g < 1:
            raise ConfigError(f"depth.bootstrap must be in [0, 1) (0: the one-step target), got {g!r}")
        if g and k != 1:
            raise ConfigError(f"depth.bootstrap {g}: a one-step Depth-Q-Net's (lookahead 1), got lookahead "
                              f"{k}")

    def step_weights(self) -> tuple[float, ...]:
        """The loss weight of each lookahead step, t+1 first."""
        return tuple(float(self.lookahead_discount) ** k for k in range(self.lookahead))


@dataclass(frozen=True)
class Selection:
    """Depth-Q-Net's own acting settings (`Network.Acting`): how its policy makes and scores its
    candidates, an evaluation's settings, not a training's.

    Switched sequences are off by default: the policy re-plans every frame, so holding is what it
    commits to, and OU exploration (a step-to-step correlation of 0.95) rarely reverses within K
    frames, so switched sequences are predicted from few training examples."""

    # How a lookahead Depth-Q-Net scores its candidate sequences: discounted_nearest_bin or
    # farthest_nearest_bin (docs/design.md#lookahead-selection). A one-step net's choice is the same
    # under each rule.
    rule: DepthRule = "discounted_nearest_bin"
    # The step weight's base of discounted_nearest_bin.
    discount: float = 0.9
    # A lookahead Depth-Q-Net also scores sequences that switch action once.
    switch: bool = False

    def __post_init__(self) -> None:
        check_choices(self, "depth")  # rule
        d = self.discount
        if isinstance(d, bool) or not isinstance(d, int | float) or not 0 < d <= 1:
            raise ConfigError(f"depth.discount must be in (0, 1], got {d!r}")
        if not isinstance(self.switch, bool):
            raise ConfigError(f"depth.switch must be true or false, got {self.switch!r}")


@register_network
class DepthQNet(Network[DepthSettings]):
    name = "depth"
    title = "Depth-Q-Net"
    label = "DQN"
    colour = "tab:blue"
    lr = 0.1  # the original's (docs/design.md#training)
    Settings = DepthSettings
    Acting = Selection
    target = bins_target
    outputs_bins = True
    metric = "abs_diff"
    metric_title = "abs diff"
    loss_title = "L1 on valid bins (m)"
    rule = "farthest_nearest_bin"
    rule_text = RULES[rule]
    maximise = True
    # Depth-Q-Net's metres below 10 carry up to ~5e-6 of the last-bit noise a batch's sums add
    # (docs/design.md#lockstep), hence 1e-5: a tie stays one whichever kernel computed the scores.
    tie_tol = 1e-5
    comparable_scores = True
    decisive = 0.01  # m: an oracle's step is decisive when its best and worst candidates differ by more
    onnx_output = "bins"
    plot = ValuePlot("bins", "depth (m)", (0.0, 2.2))
    featured = True
    paper: ClassVar[dict[int, tuple[float, float]]] = {
        50: (1.68, 0.0), 100: (4.91, 0.7), 200: (12.19, 8.0), 500: (21.96, 20.0),
        700: (22.21, 20.0), 900: (22.30, 20.0),
    }

    def check_training(self, config: Training) -> None:
        """Its lookahead fits the shortest usable run; a bootstrapped target needs a frozen trunk's
        cached features (the next frame's, for the target network)."""
        settings: DepthSettings = config.settings
        samples = config.samples
        steps = samples.min_frames - samples.horizon - 1 - samples.action_lag  # in the shortest usable run
        if settings.lookahead > steps:
            raise ConfigError(
                f"depth.lookahead {settings.lookahead} is more steps than the shortest usable run has after "
                f"a sample (min_frames - horizon - 1 - action_lag = {steps}): raise samples.min_frames "
                "or lower it"
            )
        if settings.bootstrap and (not TRUNKS[config.trunk].frozen or config.tune_stages):
            raise ConfigError(
                f"depth.bootstrap {settings.bootstrap}: a Depth-Q-Net on a frozen trunk's cached features "
                f"only (trunk {config.trunk!r}, tune_stages {config.tune_stages}); use 0"
            )

    def head_config(self, head: HeadConfig, settings: DepthSettings) -> HeadConfig:
        return replace(head, lookahead=settings.lookahead, form=settings.head_form,
                       output_bias=settings.output_bias, bin_gradient=settings.bin_gradient)

    def check_head(self, config: HeadConfig) -> None:
        if config.form != "concat" and config.lookahead != 1:
            raise ConfigError(f"HeadConfig.form {config.form!r} is a one-step Depth-Q-Net's (lookahead 1), "
                              f"got lookahead {config.lookahead!r}")

    def build_head(self, config: HeadConfig) -> Head:
        return DepthFirstHead(config) if config.form == "depth_first" else DepthHead(config)

    def samples(
        self, dataset: Dataset, split: str, n_runs: int | None, config: Training, labels: str | None = None
    ) -> dict[str, np.ndarray]:
        """Its samples, each with its lookahead's K steps (`bins_target`)."""
        return view_arrays(dataset, split, n_runs, bins_target, config.samples, config.settings.lookahead,
                           config.labels if labels is None else labels)

    def loss_function(self, settings: DepthSettings) -> LossFn:
        """L1 over the valid bins (`depth_loss`); a lookahead net's weights its steps."""
        if settings.lookahead > 1:
            weights = torch.tensor(settings.step_weights())
            return functools.partial(lookahead_l1_loss, step_weights=weights, reduction=settings.depth_loss)
        return self.step_loss(settings)

    def step_loss(self, settings: DepthSettings) -> LossFn:
        return functools.partial(depth_l1_loss, reduction=settings.depth_loss)

    def bootstrap(self, settings: DepthSettings) -> float:
        return float(settings.bootstrap)

    def candidates(self, actions: np.ndarray, lookahead: int, acting: Selection) -> np.ndarray:
        """A lookahead net's sequences: each action held, and with `acting.switch` each that switches
        once (docs/design.md#lookahead-selection)."""
        actions = np.asarray(actions, np.float64)
        return actions if lookahead == 1 else candidate_sequences(actions, lookahead, acting.switch)

    def scores(self, values: np.ndarray, acting: Selection | None = None) -> np.ndarray:
        acting = acting or Selection()
        return sequence_scores(values, acting.rule, acting.discount)

    def true_scores(self, bins: np.ndarray, bumped: np.ndarray, acting: Selection) -> np.ndarray:
        return sequence_scores(bins, acting.rule, acting.discount)
