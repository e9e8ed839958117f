"""Exploration data: the on-disk run format, labels, nested subsets and the views training reads.

Layers, each in a module of its own: `run` (one run in memory), `runfile` (one run on disk),
`manifest` (a dataset folder), `labels` (which frames are samples and their targets), `subsets`
(the paper's nested "first n runs"), `views` (PyTorch datasets and in-memory sample arrays),
`stats` (Table II and the dataset check). `DataConfig` gathers the settings they share: a
`SampleConfig` (`labels`: which frames are samples) and how runs are stored.
"""

from __future__ import annotations

from dataclasses import dataclass

from depthq.data.labels import SampleConfig
from depthq.data.runfile import JPEG_QUALITY
from depthq.data.subsets import PAPER_SUBSETS
from depthq.errors import ConfigError


@dataclass(frozen=True)
class DataConfig(SampleConfig):
    """How runs are stored (`jpeg_quality`) and turned into samples (`SampleConfig`'s fields), and the
    nested training subsets Table II counts (`subsets`)."""

    # JPEG quality of the stored camera frames (Pillow's, 1..95).
    jpeg_quality: int = JPEG_QUALITY
    # The nested training-set sizes, in runs, whose rows Table II shows (the paper's).
    subsets: tuple[int, ...] = PAPER_SUBSETS

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 1 <= self.jpeg_quality <= 95:
            raise ConfigError(
                f"data.jpeg_quality must be in 1..95 (Pillow's useful range), got {self.jpeg_quality}"
            )
        if not self.subsets or list(self.subsets) != sorted(set(self.subsets)) or self.subsets[0] < 1:
            raise ConfigError(f"data.subsets must be increasing positive run counts, got {self.subsets}")
