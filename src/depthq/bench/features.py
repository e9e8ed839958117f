"""Feature extraction speed end to end: JPEG decode + resize + the frozen trunk, on a dataset's frames."""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import torch

from depthq.data.manifest import Dataset
from depthq.nets.device import resolve_device
from depthq.nets.trunk import DEFAULT_TRUNK, build_trunk
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
    The first precision's figures are also the result's own keys."""
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
    return {"trunk": trunk, "device": str(where), "input_size": size, **each[precisions[0]],
            "precisions": each, "threads": torch.get_num_threads()}
