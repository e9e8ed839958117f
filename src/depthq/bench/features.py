"""Feature extraction speed end to end: JPEG decode + resize + the frozen trunk, on a dataset's frames."""

from __future__ import annotations

import itertools
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from depthq.blocks.device import resolve_device
from depthq.blocks.trunk import DEFAULT_TRUNK, build_trunk
from depthq.checksum import file_sha256
from depthq.data.manifest import Dataset
from depthq.train.config import check_precisions
from depthq.train.features import BATCH as DECODE_BATCH
from depthq.train.features import frame_batches, prefetch, trunk_threads


def bench_features(
    data: Path, n: int = 512, size: int = 128, trunk: str = DEFAULT_TRUNK, device: str = "auto",
    precisions: tuple[str, ...] = ("fp32",),
) -> dict:
    """Frames/s of the feature cache's pipeline on the first `n` frames of a dataset: JPEG decode and
    resize in a background thread, the frozen trunk in the caller's, as `load_features` runs them;
    once per precision ("bf16": the trunk under bfloat16 autocast, measured only: the cache is fp32's).
    The first precision's figures are also the result's own keys. `check`: what checking the cache
    costs whenever it is read (the SHA-256 of its array, from disk), in frames/s and as a share of
    computing the same frames' features."""
    check_precisions(precisions, "bench features")
    torch.set_num_threads(trunk_threads())
    dataset = Dataset.open(Path(data))
    where = resolve_device(device)
    net = build_trunk(trunk).to(where)
    each = {}
    for precision in precisions:
        frames = 0
        bf16 = precision == "bf16"
        with torch.inference_mode(), torch.autocast(where.type, dtype=torch.bfloat16, enabled=bf16):
            net(torch.rand(16, 3, size, size, device=where)).cpu()  # warm-up
            start = time.perf_counter()
            batches = itertools.islice(frame_batches(dataset, size), -(-n // DECODE_BATCH))
            for batch in prefetch(batches, depth=2):
                batch = batch[: n - frames]  # the first `n` frames, not the rest of their batch
                net(batch.to(where)).cpu()  # to the cache's memory, as `compute_features` does
                frames += len(batch)
            seconds = time.perf_counter() - start
        each[precision] = {"frames": frames, "seconds": round(seconds, 2),
                           "frames_per_s": round(frames / seconds, 1)}
    check = _check_cost(frames, net.feature_dim, each[precisions[0]]["frames_per_s"])
    return {"trunk": trunk, "device": str(where), "input_size": size, **each[precisions[0]],
            "precisions": each, "threads": torch.get_num_threads(), "check": check}


def _check_cost(frames: int, feature_dim: int, compute_frames_per_s: float, repeats: int = 5) -> dict:
    """The cache check's speed on a float16 array of `frames` rows written to disk (the fastest of
    `repeats` reads: the page cache holds a cache just used, as it does a training's)."""
    rows = np.random.default_rng(0).standard_normal((frames, feature_dim)).astype(np.float16)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "features.f16.npy"
        np.save(path, rows)
        best = float("inf")
        for _ in range(repeats):
            start = time.perf_counter()
            file_sha256(path)
            best = min(best, time.perf_counter() - start)
    rate = frames / best
    return {"frames_per_s": round(rate, 1), "mb_per_s": round(rows.nbytes / best / 1e6, 1),
            "share_of_compute": round(compute_frames_per_s / rate, 5)}
