"""Collection throughput including storage (JPEG + HDF5 + manifest), with 1 and W workers."""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path

from depthq.data.recorder import CollectConfig, collect


def bench_collect(runs: int = 20, workers: tuple[int, ...] = (1, 2), look: str | None = None) -> dict:
    """Frames stored per second for each worker count (same runs, so the same work), in `look` (None:
    the paper family's own)."""
    config = CollectConfig(runs=runs, val_runs=0)
    if look is not None:
        config = replace(config, env=replace(config.env, world=replace(config.env.world, look=look)))
    result: dict = {"runs": runs, "look": config.env.world.look}
    for w in workers:
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            dataset = collect(
                Path(tmp) / "ds", config, workers=w, progress=False
            )
            seconds = time.perf_counter() - start
            frames = sum(e.n_frames for e in dataset.entries())
            stored = sum(e.bytes for e in dataset.entries())
        result[f"w{w}"] = {
            "frames": frames,
            "seconds": round(seconds, 2),
            "steps_per_s": round(frames / seconds, 1),
            "steps_per_s_per_worker": round(frames / seconds / w, 1),
            "kb_per_frame": round(stored / frames / 1000, 1),
        }
    if len(workers) > 1:
        result["speedup"] = round(
            result[f"w{workers[-1]}"]["steps_per_s"] / result[f"w{workers[0]}"]["steps_per_s"], 2
        )
    return result
