"""One table cell of the experiments' Markdown: the mean over seeds and its 95 % interval, so every
table of docs/ spells a result the same way."""

from __future__ import annotations

import numpy as np

from depthq.report.tables import interval


def mean_interval(values: list[float], fmt: str, seeds: int | None = None) -> str:
    """'mean [low, high]' (the 95 % Student-t interval, from 2 values on); '–' for no value. With
    `seeds`, the cell says how many of them it holds when some are missing."""
    if not values:
        return "–"
    text = f"{np.mean(values):{fmt}}"
    if (ci := interval(values)) is not None:
        text += f" [{ci[0]:{fmt}}, {ci[1]:{fmt}}]"
    return text + ("" if seeds is None or len(values) == seeds else f" ({len(values)} of {seeds} seeds)")
