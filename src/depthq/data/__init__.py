"""Exploration data: the on-disk run format, samples and their targets, subsets, the views training reads.

Layers, each in a module of its own: `run` (one run in memory), `runfile` (one run on disk),
`manifest` (a dataset folder), `samples` (which frames are samples and their targets), `subsets`
(the paper's nested "first n runs"), `views` (PyTorch datasets and in-memory sample arrays),
`stats` (Table II and the dataset check). `StorageConfig` is what a collection stores (it changes
the data); `DataConfig` is how Table II counts a dataset's samples: a `SampleConfig` (`samples`: which
frames are samples, the setting a training holds as `TrainConfig.samples`) and the nested subsets.
"""

from __future__ import annotations

from dataclasses import dataclass

from depthq.data.runfile import JPEG_QUALITY
from depthq.data.samples import HORIZON, MIN_FRAMES, SampleConfig, check_min_frames
from depthq.data.subsets import PAPER_SUBSETS
from depthq.errors import ConfigError


@dataclass(frozen=True)
class StorageConfig:
    """What a collection stores besides its env (`CollectConfig.data`): the runs that count towards its
    `runs` (`min_frames`) and how their frames are stored (`jpeg_quality`). Only what changes the data:
    which frames become samples, and their targets, is a training's setting (`TrainConfig.samples`)."""

    # Runs shorter than this many frames are stored but do not count towards the runs collected.
    min_frames: int = MIN_FRAMES
    # JPEG quality of the stored camera frames (Pillow's, 1..95).
    jpeg_quality: int = JPEG_QUALITY

    def __post_init__(self) -> None:
        check_min_frames(self.min_frames, HORIZON, "data.min_frames")  # under the default targets
        if not 1 <= self.jpeg_quality <= 95:
            raise ConfigError(
                f"data.jpeg_quality must be in 1..95 (Pillow's useful range), got {self.jpeg_quality}"
            )


@dataclass(frozen=True)
class DataConfig(SampleConfig):
    """How Table II counts a dataset (`depthq dataset stats`): which frames are samples
    (`SampleConfig`'s fields, a training's `TrainConfig.samples`) in the nested training subsets
    (`subsets`)."""

    # The nested training-set sizes, in runs, whose rows Table II shows (the paper's).
    subsets: tuple[int, ...] = PAPER_SUBSETS

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.subsets or list(self.subsets) != sorted(set(self.subsets)) or self.subsets[0] < 1:
            raise ConfigError(f"data.subsets must be increasing positive run counts, got {self.subsets}")
