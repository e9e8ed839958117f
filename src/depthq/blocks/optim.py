"""The paper's optimizer: Adadelta with TensorFlow's constants, weight decay on conv weights only."""

from __future__ import annotations

from torch import nn

from depthq.blocks.adadelta import BlockedAdadelta
from depthq.errors import ConfigError

# TensorFlow's Adadelta defaults; PyTorch's are rho=0.9, eps=1e-6.
RHO = 0.95
EPS = 1e-8
WEIGHT_DECAY = 4e-5


def make_optimizer(model: nn.Module, lr: float, weight_decay: float = WEIGHT_DECAY, rho: float = RHO,
                   eps: float = EPS) -> BlockedAdadelta:
    """Adadelta (stepped block by block, see `depthq.blocks.adadelta`) over the trainable parameters
    of `model`; frozen ones are left out.

    Weight decay (gradient += wd · w, the same as TF's l2_regularizer(wd) on tf.nn.l2_loss) applies
    to nn.Conv2d weights only, as in the paper; heads (Linear layers), biases and BatchNorm get none.
    """
    if not lr > 0:
        raise ConfigError(f"learning rate must be > 0, got {lr!r}")
    if not weight_decay >= 0:
        raise ConfigError(f"weight_decay must be ≥ 0, got {weight_decay!r}")
    conv_weights = {id(m.weight) for m in model.modules() if isinstance(m, nn.Conv2d)}
    decay, no_decay = [], []
    for param in model.parameters():
        if param.requires_grad:
            (decay if id(param) in conv_weights else no_decay).append(param)
    groups = [
        {"params": params, "weight_decay": wd}
        for params, wd in ((decay, weight_decay), (no_decay, 0.0))
        if params
    ]
    if not groups:
        raise ConfigError("make_optimizer: the model has no trainable parameters")
    return BlockedAdadelta(groups, lr=lr, rho=rho, eps=eps)
