"""The paper's optimizer: Adadelta with TensorFlow's constants, weight decay on conv weights only."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable

import torch
from torch import nn
from torch._dynamo.exc import BackendCompilerFailed
from torch.optim.adadelta import adadelta

from depthq.errors import ConfigError

# TensorFlow's Adadelta defaults; PyTorch's are rho=0.9, eps=1e-6.
RHO = 0.95
EPS = 1e-8
WEIGHT_DECAY = 4e-5


def make_optimizer(model: nn.Module, lr: float, weight_decay: float = WEIGHT_DECAY) -> torch.optim.Adadelta:
    """Adadelta over the trainable parameters of `model`; frozen ones are left out.

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
    return torch.optim.Adadelta(groups, lr=lr, rho=RHO, eps=EPS)


@functools.cache
def _compiled_adadelta() -> Callable[..., None]:
    """torch.compile'd functional Adadelta; created on first use, so importing this module stays cheap.

    Tensors are its arguments, so a new optimizer over tensors of the same shapes and lr reuses the
    compiled code (compiling `optimizer.step` itself guards on the optimizer object: it recompiles
    for every model and, after 8, silently runs eagerly). Static shapes: the kernels inductor made
    for dynamic ones ran several times slower here.
    """
    return torch.compile(adadelta, dynamic=False)


def compiled_step(optimizer: torch.optim.Adadelta) -> Callable[[], None]:
    """A step function making `optimizer.step()`'s update on its state, fused by torch.compile.

    Why: eager Adadelta makes ~11 elementwise passes over every tensor; for a head's 5.3 M
    parameters that is memory-bound and takes longer than the head's forward and backward together
    (≈ 20 ms vs 12 ms at batch 64 on the 2-core reference CPU); fused, it takes ≈ 2.5 ms. The first
    call in a process compiles (≈ 20 s; a few seconds once inductor's on-disk cache is warm). Where
    compiling is impossible (no C++ compiler) it warns once and runs the same function eagerly.
    """
    if not isinstance(optimizer, torch.optim.Adadelta):
        raise ConfigError(f"compiled_step: expected torch.optim.Adadelta, got {type(optimizer).__name__}")
    update = _compiled_adadelta()

    @torch.no_grad()
    def step() -> None:
        nonlocal update
        for group in optimizer.param_groups:
            params = [p for p in group["params"] if p.grad is not None]
            states = [optimizer.state[p] for p in params]
            for p, state in zip(params, states, strict=True):
                if not state:  # the lazy initialisation Adadelta.step does
                    state["step"] = torch.zeros(())
                    state["square_avg"] = torch.zeros_like(p, memory_format=torch.preserve_format)
                    state["acc_delta"] = torch.zeros_like(p, memory_format=torch.preserve_format)
            args = (
                params,
                [p.grad for p in params],
                [s["square_avg"] for s in states],
                [s["acc_delta"] for s in states],
                [s["step"] for s in states],
            )
            hyper = {k: group[k] for k in ("lr", "rho", "eps", "weight_decay", "maximize")}
            try:
                update(*args, foreach=False, **hyper)
            except BackendCompilerFailed as err:  # raised while compiling, before this group's update
                warnings.warn(f"optimizer step not compiled ({err}); stepping eagerly", stacklevel=2)
                update = adadelta
                update(*args, foreach=False, **hyper)

    return step
