"""Where an experiment's time goes: `timed` adds a step's wall-clock seconds to FOLDER/times.json, for
the steps a sweep's own stages.json does not time (a recipe's collection and re-rendering, a labeller,
its labels, the nets trained on them). A shared helper of research/, not a command."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from depthq.configio import read_json, write_json

TIMES = "times.json"


@contextmanager
def timed(folder: Path, step: str, done: bool = False) -> Iterator[None]:
    """`step`'s wall-clock seconds added to folder/times.json when it returns, unless it was `done`
    before it began (a resumed job rewrites nothing it finished); an interrupted step's total is the
    sum of its tries."""
    start = time.monotonic()
    yield
    if done:
        return
    path = Path(folder) / TIMES
    times = read_json(path) if path.is_file() else {}
    times[step] = round(times.get(step, 0.0) + time.monotonic() - start, 1)
    write_json(path, times)
