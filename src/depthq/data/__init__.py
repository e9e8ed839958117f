"""Exploration data: the on-disk run format, labels, nested subsets and the views training reads.

Layers, each in a module of its own: `run` (one run in memory), `runfile` (one run on disk),
`manifest` (a dataset folder), `labels` (which frames are samples and their targets), `subsets`
(the paper's nested "first n runs"), `views` (PyTorch datasets and in-memory sample arrays),
`stats` (Table II and the dataset check). `DataConfig` gathers the settings they share.
"""

from __future__ import annotations

from dataclasses import dataclass

from depthq.data.labels import HORIZON, MIN_FRAMES
from depthq.data.runfile import JPEG_QUALITY
from depthq.data.subsets import PAPER_SUBSETS
from depthq.errors import ConfigError


@dataclass(frozen=True)
class DataConfig:
    """How runs are stored (`jpeg_quality`) and turned into samples (the rest; see `depthq.data.labels`).

    The defaults are the original's: collision labels on the last `horizon` samples of every run
    (`every_run_end`), and the stored command clipped to ±`action_clip` as the action label.
    """

    horizon: int = HORIZON
    min_frames: int = MIN_FRAMES
    jpeg_quality: int = JPEG_QUALITY
    subsets: tuple[int, ...] = PAPER_SUBSETS
    every_run_end: bool = True
    action_clip: float = 1.0
    action_lag: int = 0

    def __post_init__(self) -> None:
        if self.horizon < 1:
            raise ConfigError(f"data.horizon must be >= 1, got {self.horizon}")
        if self.min_frames < self.horizon + 2:
            raise ConfigError(
                f"data.min_frames must be >= horizon + 2 = {self.horizon + 2} so every usable run keeps "
                f"a depth sample, got {self.min_frames}"
            )
        if not 1 <= self.jpeg_quality <= 95:
            raise ConfigError(
                f"data.jpeg_quality must be in 1..95 (Pillow's useful range), got {self.jpeg_quality}"
            )
        if not self.action_clip > 0:
            raise ConfigError(f"data.action_clip must be > 0 rad/s, got {self.action_clip}")
        if self.action_lag not in (0, 1):
            raise ConfigError(f"data.action_lag must be 0 or 1, got {self.action_lag}")
        if not self.subsets or list(self.subsets) != sorted(set(self.subsets)) or self.subsets[0] < 1:
            raise ConfigError(f"data.subsets must be increasing positive run counts, got {self.subsets}")
