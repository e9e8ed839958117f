"""The experiments' command lines: bad input or data is one line on stderr and its exit status
(`depthq.errors.explain`, as the `depthq` verbs do); anything else, a bug, is shown in full."""

from __future__ import annotations

import sys
from collections.abc import Callable

from depthq.errors import explain


def guarded(prog: str, work: Callable[[], int]) -> int:
    """`work()`'s exit status, or the status and one line `explain` gives for what it raised."""
    try:
        return work()
    except Exception as err:
        status, line = explain(err)
        if status is None:
            raise
        print(f"{prog}: {line}", file=sys.stderr)
        return status
