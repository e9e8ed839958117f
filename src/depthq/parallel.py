"""Worker processes shared by collection and evaluation: spawned (EGL contexts do not survive a fork)."""

from __future__ import annotations

import queue
from multiprocessing.process import BaseProcess
from typing import Any


def next_result(results, procs: list[BaseProcess], what: str) -> Any:
    """The next item a worker put on `results`; an error instead of a hang when every worker died."""
    while True:
        try:
            return results.get(timeout=5)
        except queue.Empty:
            if not any(p.is_alive() for p in procs):
                raise RuntimeError(f"all {what} workers died; run the same command to resume") from None
