"""Re-rendering throughput: a collected dataset's runs rendered again in other looks, with storage."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from depthq.data.recorder import CollectConfig, collect
from depthq.data.rerender import rerender


def bench_rerender(runs: int = 10, looks: tuple[str, ...] = ("textured", "broad"), workers: int = 1) -> dict:
    """Frames re-rendered and stored per second, and KB stored per frame, in each of `looks` on `workers`
    processes, of `runs` runs collected first in the paper family's own look (timed too: the collector's
    frames/s, a step and a frame, beside them)."""
    result: dict = {"runs": runs, "workers": workers, "looks": {}}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "ds"
        start = time.perf_counter()
        dataset = collect(root, CollectConfig(runs=runs, val_runs=0), workers=workers, progress=False)
        seconds = time.perf_counter() - start
        frames = sum(e.n_frames for e in dataset.entries())
        result["collect"] = {"look": dataset.config["env"]["world"]["look"], "frames": frames,
                             "frames_per_s": round(frames / seconds, 1)}
        for look in looks:
            start = time.perf_counter()
            dataset = rerender(root, (look,), seed=1, workers=workers, progress=False)
            seconds = time.perf_counter() - start
            new = [e for e in dataset.entries() if e.rendered is not None and e.rendered.look == look]
            n = sum(e.n_frames for e in new)
            result["looks"][look] = {"frames": n, "seconds": round(seconds, 2),
                                     "frames_per_s": round(n / seconds, 1),
                                     "ms_per_frame": round(1000 * seconds / n, 1),
                                     "kb_per_frame": round(sum(e.bytes for e in new) / n / 1000, 1)}
    return result
