"""Worker processes shared by collection and evaluation (spawned: EGL contexts do not survive a fork),
and the core count that sizes thread pools."""

from __future__ import annotations

import os
import queue
from multiprocessing.process import BaseProcess
from typing import Any


def cores() -> int:
    """The CPU cores this process may run on (its affinity, not the machine's count)."""
    return len(os.sched_getaffinity(0))


def next_result(results, procs: list[BaseProcess], what: str) -> Any:
    """The next item a worker put on `results`; an error instead of a hang when every worker died."""
    while True:
        try:
            return results.get(timeout=5)
        except queue.Empty:
            if not any(p.is_alive() for p in procs):
                raise RuntimeError(f"all {what} workers died; run the same command to resume") from None
