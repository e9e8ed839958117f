"""Collection throughput including storage (JPEG + HDF5 + manifest), with 1 and W workers."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from depthq.data.recorder import CollectConfig, collect


def bench_collect(runs: int = 20, workers: tuple[int, ...] = (1, 2)) -> dict:
    """Frames stored per second for each worker count (same runs, so the same work)."""
    result: dict = {"runs": runs}
    for w in workers:
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            dataset = collect(
                Path(tmp) / "ds", CollectConfig(runs=runs, val_runs=0), workers=w, progress=False
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
