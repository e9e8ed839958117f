"""Micro benchmarks of the networks (SPEC §4): trunk feature extraction and head training speed.

Each timed unit is repeated and both the overall rate and the best repetition are returned: on a
shared 2-core machine the best repetition is the closest to what the code itself can do, the
overall rate is what a run would have seen.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import torch

from depthq.nets.heads import COLL_HIDDEN, HeadConfig, HeadKind, build_head
from depthq.nets.losses import coll_bce_loss, depth_l1_loss
from depthq.nets.optim import compiled_step, make_optimizer
from depthq.nets.trunk import FROZEN_MICRO_BATCH, build_trunk, preprocess

CAMERA_HW = (308, 410)


@contextmanager
def _threads(threads: int | None) -> Iterator[int]:
    """Run with `threads` torch threads (default: every core this process may use), then restore."""
    before = torch.get_num_threads()
    threads = threads or len(os.sched_getaffinity(0))
    torch.set_num_threads(threads)
    try:
        yield threads
    finally:
        torch.set_num_threads(before)


def _times(fn: Callable[[], object], repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return out


def bench_features(
    n_frames: int = 512, batch: int = 64, size: int = 128, threads: int | None = None
) -> dict[str, Any]:
    """EfficientNet-Lite0 (frozen, ImageNet weights) features per second on CPU, and preprocessing speed.

    With other processes busy on the same cores, fewer threads can be much faster (OpenMP threads
    wait for each other at every layer), hence `threads`.
    """
    with _threads(threads) as n_threads, torch.inference_mode():
        trunk = build_trunk("efficientnet_lite0")
        gen = torch.Generator().manual_seed(0)
        images = torch.rand(batch, 3, size, size, generator=gen)
        trunk(images)  # warm-up: oneDNN builds its kernels for these shapes
        n_batches = max(1, -(-n_frames // batch))
        times = _times(lambda: trunk(images), n_batches)
        frames = np.random.default_rng(0).integers(0, 256, (batch, *CAMERA_HW, 3), dtype=np.uint8)
        preprocess(frames, size)
        pre_times = _times(lambda: preprocess(frames, size), n_batches)
    return {
        "trunk": trunk.name,
        "size": size,
        "batch": batch,
        "micro_batch": FROZEN_MICRO_BATCH,
        "n_frames": n_batches * batch,
        "threads": n_threads,
        "frames_per_s": n_batches * batch / sum(times),
        "frames_per_s_best": batch / min(times),
        "frames_per_s_median": batch / statistics.median(times),
        "preprocess_frames_per_s": n_batches * batch / sum(pre_times),
        "preprocess_from": list(CAMERA_HW),
        "target_frames_per_s": 300,
    }


def bench_head(
    kind: HeadKind = "depth",
    feature_dim: int = 1280,
    batch: int = 64,
    steps: int = 40,
    lr: float = 0.1,
    threads: int | None = None,
) -> dict[str, Any]:
    """Head training speed (forward + backward + Adadelta step on cached features) against the
    FLOP/s of a plain `torch.matmul` of the head's first-layer shape, all interleaved in one run so
    that every timing sees the same machine load. Measured with the compiled optimizer step (what
    training should use) and with the eager one.

    Head FLOPs per sample are counted as 3× the forward matmul FLOPs (forward + two backward
    matmuls). On cached features no input gradient is needed, so the work really done is ~2×:
    `ratio_2x_count` is the ratio under that count.
    """
    config = HeadConfig(kind, feature_dim)
    gen = torch.Generator().manual_seed(0)
    features = torch.randn(batch, feature_dim, generator=gen)
    actions = torch.rand(batch, generator=gen) * 2 - 1
    if kind == "depth":
        target = torch.rand(batch, config.n_bins, generator=gen) * 2.5
        loss_fn, out_flops = depth_l1_loss, config.hidden * config.n_bins
    else:
        target = (torch.rand(batch, generator=gen) < 0.1).float()
        loss_fn, out_flops = coll_bce_loss, config.hidden * COLL_HIDDEN + COLL_HIDDEN

    def trainer(compiled: bool) -> Callable[[], None]:
        head = build_head(config).train()
        optimizer = make_optimizer(head, lr)
        optimizer_step = compiled_step(optimizer) if compiled else optimizer.step

        def train_step() -> None:
            optimizer.zero_grad(set_to_none=True)
            loss_fn(head(features, actions), target)[0].backward()
            optimizer_step()

        return train_step

    x = torch.randn(batch, feature_dim + 1, generator=gen)
    w = torch.randn(feature_dim + 1, config.hidden, generator=gen)
    with _threads(threads) as n_threads:
        fused, eager = trainer(compiled=True), trainer(compiled=False)
        compile_s = sum(_times(fused, 1))  # the first call compiles the optimizer step
        units = {"fused": fused, "eager": eager, "matmul": lambda: torch.matmul(x, w)}
        for _ in range(2):
            for unit in units.values():
                unit()
        times: dict[str, list[float]] = {name: [] for name in units}
        for _ in range(steps):
            for name, unit in units.items():
                times[name] += _times(unit, 1)
    head_flops = 3 * 2 * ((feature_dim + 1) * config.hidden + out_flops) * batch
    mm_flops = 2 * batch * (feature_dim + 1) * config.hidden
    mm_rate = mm_flops * steps / sum(times["matmul"])
    ratio = head_flops * steps / sum(times["fused"]) / mm_rate
    return {
        "kind": kind,
        "feature_dim": feature_dim,
        "batch": batch,
        "steps": steps,
        "threads": n_threads,
        "samples_per_s": batch * steps / sum(times["fused"]),
        "samples_per_s_best": batch / min(times["fused"]),
        "head_gflop_per_s": head_flops * steps / sum(times["fused"]) / 1e9,
        "matmul_gflop_per_s": mm_rate / 1e9,
        "ratio": ratio,
        "ratio_best": head_flops / min(times["fused"]) / (mm_flops / min(times["matmul"])),
        "ratio_2x_count": ratio * 2 / 3,
        "samples_per_s_eager_step": batch * steps / sum(times["eager"]),
        "ratio_eager_step": head_flops * steps / sum(times["eager"]) / mm_rate,
        "compile_s": compile_s,
        "target_ratio": 0.6,
    }
