"""Progress bars: tqdm's on a terminal; elsewhere (a log file, CI) silent while they run and one line
each when they end, so a log holds one line per bar, never a bar redrawn or drawn backwards."""

from __future__ import annotations

import math
import sys
from typing import Any

from tqdm import tqdm


class Bar(tqdm):
    """A tqdm bar, with tqdm's arguments; when its stream is not a terminal, only its final state is
    written (one line, on `close`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._quiet = not is_terminal(kwargs.get("file") or sys.stderr)
        self._closing = False
        if self._quiet:
            kwargs.update(mininterval=math.inf, dynamic_ncols=False, leave=True)
        super().__init__(*args, **kwargs)

    def display(self, msg: str | None = None, pos: int | None = None) -> bool | None:
        if self._quiet and not self._closing:
            return None
        return super().display(msg, pos)

    def clear(self, nolock: bool = False) -> None:
        if not self._quiet:
            super().clear(nolock)

    def close(self) -> None:
        self._closing = True
        super().close()


def is_terminal(stream: Any) -> bool:
    """Whether `stream` is a terminal (a closed or file-less stream is not)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False
