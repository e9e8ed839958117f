"""One table cell of the experiments' Markdown: the mean over seeds and its 95 % interval, so every
table of docs/ spells a result the same way; and the evaluation summary a cell is read from."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from depthq.configio import read_json
from depthq.report.tables import interval


def evaluation_summary(folder: Path) -> dict[str, Any] | None:
    """The `summary` of the evaluation folder `folder` (`depthq evaluate --out`); None if not written yet."""
    path = Path(folder) / "summary.json"
    return read_json(path)["summary"] if path.is_file() else None


def mean_interval(values: list[float], fmt: str, seeds: int | None = None) -> str:
    """'mean [low, high]' (the 95 % Student-t interval, from 2 values on); '–' for no value. With
    `seeds`, the cell says how many of them it holds when some are missing."""
    if not values:
        return "–"
    text = f"{np.mean(values):{fmt}}"
    if (ci := interval(values)) is not None:
        text += f" [{ci[0]:{fmt}}, {ci[1]:{fmt}}]"
    return text + ("" if seeds is None or len(values) == seeds else f" ({len(values)} of {seeds} seeds)")
