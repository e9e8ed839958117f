"""Head training speed on cached features: samples/s and the FLOP/s it reaches as a fraction of matmul's;
and a tuned trunk's (its late stages and the head on cached activations: `TrainConfig.tune_stages`).
(The other half of training, feature extraction, is `depthq.bench.features`.)"""

from __future__ import annotations

import time

import numpy as np
import torch

from depthq.blocks.device import resolve_device
from depthq.blocks.heads import QNet
from depthq.blocks.losses import depth_l1_loss
from depthq.blocks.optim import make_optimizer
from depthq.blocks.trunk import STAGES, build_trunk, early_map_shape
from depthq.networks import DepthQNet, DepthSettings, build_head
from depthq.parallel import cores
from depthq.train.config import TrainConfig, check_precisions
from depthq.train.features import FeatureTable
from depthq.train.samples import ActivationSamples, FeatureSamples, Samples
from depthq.train.trainer import train_step

BATCH = 64
POOL = 8192  # cached-feature-like rows to draw batches from
ACTIVATION_POOL = 1024  # cached-activation-like rows (up to 20 KB each) to draw a tuned trunk's batches from
ROOFLINE_HIDDEN = 4096  # the GEMM the ratios are taken against: 1281 × 4096, whatever the heads' widths


def bench_train(
    seconds: float = 10.0, device: str = "auto", precisions: tuple[str, ...] = ("fp32",),
    threads: int | None = None, forms: tuple[str | None, ...] = (None,),
    hiddens: tuple[int | None, ...] = (None,), tunes: tuple[int, ...] = (0,),
) -> dict:
    """Depth-Q-Net head training samples/s (batch 64, 1280-d features, Adadelta) and its FLOP/s as a
    fraction of what fp32 `torch.matmul` reaches on a 1281 × 4096 GEMM in the same run, for each head
    form of `forms` (`TrainConfig.head_form`; None: the default), each hidden width of `hiddens`
    (`TrainConfig.hidden`; None: the default), each of `tunes` (`TrainConfig.tune_stages`: the last N
    trunk stages trained too, from cached activations of the default input size; 0: the head alone)
    and each of `precisions` (`TrainConfig.precision`), their rounds interleaved so that all see the
    same machine load; `threads` None: this process's cores. The first variant's figures are also the
    result's own keys; `variants` holds each as "FORM/PRECISION", with "/HIDDEN" after it when widths
    are given and "/tuneN" when `tunes` are.

    Head FLOPs per sample follow the usual 3 × forward convention (`ratio`); a layer fed data (the
    feature, a depth-first head's true current bins) needs no input gradient, so `ratio_actual`
    counts the work really done. Both count the head's linear layers only, not a tuned trunk's stages.
    """
    check_precisions(precisions, "bench train")
    where = resolve_device(device)
    torch.set_num_threads(threads or cores())
    torch.set_flush_denormal(True)  # as `train` does
    torch.manual_seed(0)
    widths = [{} if hidden is None else {"hidden": hidden} for hidden in dict.fromkeys(hiddens)]
    configs = [TrainConfig(model=DepthQNet.name, data="-", settings=DepthSettings(head_form=form),
                           tune_stages=tune, **width)
               for form in dict.fromkeys(forms) for width in widths for tune in dict.fromkeys(tunes)]
    variants = [(config, precision) for config in configs for precision in precisions]
    names = [f"{config.head().form}/{precision}" + ("" if hiddens == (None,) else f"/{config.hidden}")
             + ("" if tunes == (0,) else f"/tune{config.tune_stages}") for config, precision in variants]
    models = {name: QNet(build_trunk(config.trunk, pretrained=False, tune_stages=config.tune_stages),
                         build_head(config.head())).to(where)
              for name, (config, _) in zip(names, variants, strict=True)}
    optimizers = {name: make_optimizer(models[name], config.learning_rate, config.weight_decay)
                  for name, (config, _) in zip(names, variants, strict=True)}
    head = configs[0].head()
    rng = np.random.default_rng(0)
    sources = {tune: _samples(tune, head.feature_dim, head.n_bins, rng) for tune in dict.fromkeys(tunes)}
    samples_of = {name: sources[config.tune_stages]
                  for name, (config, _) in zip(names, variants, strict=True)}
    x = torch.rand(BATCH, head.feature_dim + 1, device=where)
    w = torch.rand(head.feature_dim + 1, ROOFLINE_HIDDEN, device=where)

    def head_step(name: str, precision: str) -> None:
        samples = samples_of[name]
        batch = samples.batch(samples.draw(BATCH, rng)).to(where)
        # its loss.item() waits for the device
        train_step(models[name], samples, batch, depth_l1_loss, optimizers[name], precision)

    def matmul() -> None:
        torch.matmul(x, w).sum().item()  # .item(): wait for the device, as a training step does

    for model in models.values():
        model.train()
    head_s = dict.fromkeys(names, 0.0)
    head_n = dict.fromkeys(names, 0)
    matmul_s, matmul_n = 0.0, 0
    for _ in range(3):  # warm-up
        for name, (_, precision) in zip(names, variants, strict=True):
            head_step(name, precision)
        matmul()
    rounds = max(1, round(seconds))
    for _ in range(rounds):  # alternate, so all see the same machine load
        for name, (_, precision) in zip(names, variants, strict=True):
            n, dt = _timed(lambda a=name, p=precision: head_step(a, p), 0.75 * seconds / rounds / len(names))
            head_n[name], head_s[name] = head_n[name] + n, head_s[name] + dt
        n, dt = _timed(matmul, 0.25 * seconds / rounds)
        matmul_n, matmul_s = matmul_n + n, matmul_s + dt
    matmul_flops = matmul_n * 2 * BATCH * (head.feature_dim + 1) * ROOFLINE_HIDDEN / matmul_s
    each = {}
    for name, (config, _) in zip(names, variants, strict=True):
        forward, actual = _step_flops(models[name].head)
        samples_per_s = head_n[name] * BATCH / head_s[name]
        each[name] = {
            "tune_stages": config.tune_stages,
            "samples_per_s": round(samples_per_s, 1),
            "steps_per_s": round(head_n[name] / head_s[name], 2),
            "head_gflops": round(3 * forward * samples_per_s / 1e9, 2),
            "ratio": round(3 * forward * samples_per_s / matmul_flops, 3),
            "ratio_actual": round(actual * samples_per_s / matmul_flops, 3),
        }
    return {
        "device": str(where),
        "threads": torch.get_num_threads(),
        **each[names[0]],
        "matmul_gflops": round(matmul_flops / 1e9, 2),
        "variants": each,
        "seconds": round(sum(head_s.values()) + matmul_s, 2),
    }


def _samples(tune: int, feature_dim: int, n_bins: int, rng: np.random.Generator) -> Samples:
    """Random training samples of a head on `feature_dim`-d cached features (`tune` 0), or of a trunk
    tuning its last `tune` stages on its cached activations at the default input size."""
    pool = ACTIVATION_POOL if tune else POOL
    arrays = {
        "run_offsets": np.array([0, pool]),
        "run_id": np.zeros(pool, dtype=np.int64),
        "frame_id": np.arange(pool),
        "action": rng.uniform(-1, 1, pool).astype(np.float32),
        "target": rng.uniform(0.2, 2.5, (pool, n_bins)).astype(np.float32),
        "current": rng.uniform(0.2, 2.5, (pool, n_bins)).astype(np.float32),
    }
    if not tune:
        features = rng.uniform(0, 6, (pool, feature_dim)).astype(np.float16)
        return FeatureSamples(arrays, FeatureTable(features, {"train_000000": (0, pool)}, False), "train")
    dim = int(np.prod(early_map_shape(STAGES - tune, TrainConfig.input_size)))
    activations = rng.uniform(-3, 3, (pool, dim)).astype(np.float16)  # a projection conv's output
    return ActivationSamples(arrays, FeatureTable(activations, {"train_000000": (0, pool)}, False), "train")


def _step_flops(head: torch.nn.Module) -> tuple[int, int]:
    """A training step's FLOPs per sample in `head`'s linear layers: forward, and the work really done
    (forward, weight gradient, and an input gradient for every layer but those fed data: the first
    of each path, whose input is the feature or the true current bins)."""
    linears = [m for m in head.modules() if isinstance(m, torch.nn.Linear)]
    firsts = {id(m) for m in linears if m.in_features in (head.config.feature_dim + head.config.lookahead,
                                                          head.config.feature_dim, head.config.n_bins + 1)}
    forward = sum(2 * m.in_features * m.out_features for m in linears)
    actual = sum((2 if id(m) in firsts else 3) * 2 * m.in_features * m.out_features for m in linears)
    return forward, actual


def _timed(fn, seconds: float) -> tuple[int, float]:
    """Calls of `fn` in about `seconds`, and the time they took."""
    n, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds or n == 0:
        fn()
        n += 1
    return n, elapsed
