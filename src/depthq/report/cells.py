"""One table cell of the experiments' Markdown: the mean over seeds and its 95 % interval, so every
table of docs/ spells a result the same way; the evaluation summary a cell is read from; and a row of
how well a measure ranks the driving."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import spearmanr

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


def ranks_driving(title: str, points: list[dict[str, Any]], key: str) -> str:
    """One Markdown row: how well `key` ranks the points' distance to the first collision, Spearman's ρ
    and its p over the points that have it ('–' under 3)."""
    pairs = [(p[key], p["distance_to_collision_mean"]) for p in points if p.get(key) is not None]
    if len(pairs) < 3:
        return f"| {title} | {len(pairs)} | – | – |"
    rho, pvalue = spearmanr(*zip(*pairs, strict=True))
    return f"| {title} | {len(pairs)} | {rho:+.2f} | {pvalue:.3f} |"
