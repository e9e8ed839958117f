"""Head training speed on cached features: samples/s and the FLOP/s it reaches as a fraction of matmul's.
(The other half of training, feature extraction, is `depthq.bench.features`.)"""

from __future__ import annotations

import time

import numpy as np
import torch

from depthq.nets.device import resolve_device
from depthq.nets.heads import QNet, build_head
from depthq.nets.losses import depth_l1_loss
from depthq.nets.optim import make_optimizer
from depthq.nets.trunk import build_trunk
from depthq.parallel import cores
from depthq.train.config import TrainConfig, check_precisions
from depthq.train.features import FeatureTable
from depthq.train.samples import FeatureSamples
from depthq.train.trainer import train_step

BATCH = 64
POOL = 8192  # cached-feature-like rows to draw batches from


def bench_train(
    seconds: float = 10.0, device: str = "auto", precisions: tuple[str, ...] = ("fp32",),
    threads: int | None = None,
) -> dict:
    """Depth-Q-Net head training samples/s (batch 64, 1280-d features, 4096 hidden, Adadelta) and its
    FLOP/s as a fraction of what fp32 `torch.matmul` reaches on the head's largest GEMM in the same run,
    for each of `precisions` (`TrainConfig.precision`), their rounds interleaved so that all see the
    same machine load; `threads` None: this process's cores. The first precision's figures are also
    the result's own keys.

    Head FLOPs per sample follow the usual 3 × forward convention (`ratio`); the hidden layer's input
    gradient is never computed (features need none), so `ratio_actual` counts the work really done.
    """
    check_precisions(precisions, "bench train")
    where = resolve_device(device)
    torch.set_num_threads(threads or cores())
    torch.set_flush_denormal(True)  # as `train` does
    torch.manual_seed(0)
    config = TrainConfig(model="depth", data="-")
    head = config.head()
    models = {p: QNet(build_trunk(config.trunk, pretrained=False), build_head(head)).to(where)
              for p in precisions}
    optimizers = {p: make_optimizer(m, config.learning_rate, config.weight_decay) for p, m in models.items()}
    rng = np.random.default_rng(0)
    arrays = {
        "run_offsets": np.array([0, POOL]),
        "run_id": np.zeros(POOL, dtype=np.int64),
        "frame_id": np.arange(POOL),
        "action": rng.uniform(-1, 1, POOL).astype(np.float32),
        "target": rng.uniform(0.2, 2.5, (POOL, head.n_bins)).astype(np.float32),
    }
    features = rng.uniform(0, 6, (POOL, head.feature_dim)).astype(np.float16)
    samples = FeatureSamples(arrays, FeatureTable(features, {"train_000000": (0, POOL)}, False), "train")
    x = torch.rand(BATCH, head.feature_dim + 1, device=where)
    w = torch.rand(head.feature_dim + 1, head.hidden, device=where)

    def head_step(precision: str) -> None:
        batch = samples.batch(samples.draw(BATCH, rng)).to(where)
        # its loss.item() waits for the device
        train_step(models[precision], samples, batch, depth_l1_loss, optimizers[precision], precision)

    def matmul() -> None:
        torch.matmul(x, w).sum().item()  # .item(): wait for the device, as a training step does

    for model in models.values():
        model.train()
    head_s = dict.fromkeys(precisions, 0.0)
    head_n = dict.fromkeys(precisions, 0)
    matmul_s, matmul_n = 0.0, 0
    for _ in range(3):  # warm-up
        for precision in precisions:
            head_step(precision)
        matmul()
    rounds = max(1, round(seconds))
    for _ in range(rounds):  # alternate, so all see the same machine load
        for precision in precisions:
            n, dt = _timed(lambda p=precision: head_step(p), 0.75 * seconds / rounds / len(precisions))
            head_n[precision], head_s[precision] = head_n[precision] + n, head_s[precision] + dt
        n, dt = _timed(matmul, 0.25 * seconds / rounds)
        matmul_n, matmul_s = matmul_n + n, matmul_s + dt
    d, h, k = head.feature_dim + 1, head.hidden, head.n_bins
    forward = 2 * (d * h + h * k)  # FLOPs per sample
    actual = 2 * 2 * d * h + 3 * 2 * h * k
    matmul_flops = matmul_n * 2 * BATCH * d * h / matmul_s
    each = {}
    for precision in precisions:
        samples_per_s = head_n[precision] * BATCH / head_s[precision]
        each[precision] = {
            "samples_per_s": round(samples_per_s, 1),
            "steps_per_s": round(head_n[precision] / head_s[precision], 2),
            "head_gflops": round(3 * forward * samples_per_s / 1e9, 2),
            "ratio": round(3 * forward * samples_per_s / matmul_flops, 3),
            "ratio_actual": round(actual * samples_per_s / matmul_flops, 3),
        }
    return {
        "device": str(where),
        "threads": torch.get_num_threads(),
        **each[precisions[0]],
        "matmul_gflops": round(matmul_flops / 1e9, 2),
        "precisions": each,
        "seconds": round(sum(head_s.values()) + matmul_s, 2),
    }


def _timed(fn, seconds: float) -> tuple[int, float]:
    """Calls of `fn` in about `seconds`, and the time they took."""
    n, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds or n == 0:
        fn()
        n += 1
    return n, elapsed
