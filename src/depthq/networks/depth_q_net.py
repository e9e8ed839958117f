"""Depth-Q-Net (docs/design.md#heads): predicts, for each candidate action, the depth bins one step
later (or K steps: docs/design.md#lookahead), and acts on the action whose nearest predicted obstacle
is farthest (docs/design.md#action-selection)."""

from __future__ import annotations

import functools
from typing import Any, ClassVar

import numpy as np
import torch

from depthq.blocks.heads import DepthFirstHead, DepthHead, Head, HeadConfig
from depthq.blocks.losses import LossFn, depth_l1_loss, lookahead_l1_loss
from depthq.control.action_selection import RULES, Selection, sequence_scores
from depthq.errors import ConfigError
from depthq.networks.network import Network, ValuePlot
from depthq.networks.registry import register_network

# A one-step Depth-Q-Net's default head form (docs/oracle_gap.md#depth-first: it drives the hard `val`
# canyons twice as far as "concat"); a Depth-Q-Net looking further ahead knows only "concat".
DEFAULT_FORM = "depth_first"


@register_network
class DepthQNet(Network):
    name = "depth"
    title = "Depth-Q-Net"
    label = "DQN"
    colour = "tab:blue"
    lr = 0.1  # the original's (docs/design.md#training)
    view = "bins"
    looks_ahead = True
    bootstraps = True
    metric = "abs_diff"
    metric_title = "abs diff"
    loss_title = "L1 on valid bins (m)"
    rule = "farthest_nearest_bin"
    rule_text = RULES[rule]
    maximise = True
    # Depth-Q-Net's metres below 10 carry up to ~5e-6 of the last-bit noise a batch's sums add
    # (docs/design.md#lockstep), hence 1e-5: a tie stays one whichever kernel computed the scores.
    tie_tol = 1e-5
    uses_selection = True
    decisive = 0.01  # m: an oracle's step is decisive when its best and worst candidates differ by more
    onnx_output = "bins"
    plot = ValuePlot("bins", "depth (m)", (0.0, 2.2))
    featured = True
    paper: ClassVar[dict[int, tuple[float, float]]] = {
        50: (1.68, 0.0), 100: (4.91, 0.7), 200: (12.19, 8.0), 500: (21.96, 20.0),
        700: (22.21, 20.0), 900: (22.30, 20.0),
    }

    def default_form(self, lookahead: int) -> str:
        return DEFAULT_FORM if lookahead == 1 else "concat"

    def check_head(self, config: HeadConfig) -> None:
        self.check_lookahead(config.lookahead, "HeadConfig.lookahead")
        if config.form != "concat" and config.lookahead != 1:
            raise ConfigError(f"HeadConfig.form {config.form!r} is a one-step Depth-Q-Net's (lookahead 1), "
                              f"got lookahead {config.lookahead!r}")

    def build_head(self, config: HeadConfig) -> Head:
        return DepthFirstHead(config) if config.form == "depth_first" else DepthHead(config)

    def loss_function(self, config: Any) -> LossFn:
        """L1 over the valid bins (`config.depth_loss`); a lookahead net's weights its steps."""
        if config.lookahead > 1:
            weights = torch.tensor(config.step_weights())
            return functools.partial(lookahead_l1_loss, step_weights=weights, reduction=config.depth_loss)
        return functools.partial(depth_l1_loss, reduction=config.depth_loss)

    def scores(self, values: np.ndarray, selection: Selection | None = None) -> np.ndarray:
        return sequence_scores(values, selection)

    def true_scores(self, bins: np.ndarray, bumped: np.ndarray, selection: Selection) -> np.ndarray:
        return sequence_scores(bins, selection)
