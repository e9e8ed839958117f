"""The paper's head as tests build it: HeadConfig declares no defaults (TrainConfig does, #33)."""

from __future__ import annotations

from depthq.blocks.heads import HeadConfig

# FC 4096, dropout 0.5, the raw action appended, one step, the feature unprojected: what HeadConfig's
# defaults were, and what a checkpoint record without the later fields reads as.
PAPER = {"hidden": 4096, "dropout": 0.5, "action_scale": 1.0, "lookahead": 1, "feature_projection": 0,
         "form": "concat", "output_bias": 0.0, "bin_gradient": "relu"}


def paper_head(kind: str, feature_dim: int, **changes: object) -> HeadConfig:
    """The paper's `kind` head on a `feature_dim` feature, `changes` made."""
    return HeadConfig(kind, feature_dim, **{**PAPER, **changes})
