"""Training batches of one view, "a random run, then a random frame of it" (docs/design.md#sampling).

Three sources with one interface, so the training loop does not care which trunk it trains:

- `FeatureSamples`: a frozen trunk's cached features, held in memory (float16), batches in
  microseconds; the model runs its head only.
- `ActivationSamples`: the cached map of a tuned trunk's frozen early stages, read batch by batch;
  the model runs its late stages and its head.
- `ImageSamples`: frames decoded from the run files and resized once, held as uint8, for a trunk
  trained with the head (MobileNet-v1-0.25 from scratch, EfficientNet-Lite0 fine-tuned).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import torch

from depthq.blocks.heads import QNet
from depthq.blocks.losses import DEPTH_CLIP
from depthq.blocks.trunk import resize_frames, scale_frames
from depthq.data.views import FrameView, run_then_frame
from depthq.progress import Bar
from depthq.train.features import FeatureTable


@dataclass(frozen=True)
class Batch:
    """Model inputs (features (B, D) or images (B, 3, S, S)), actions (B,), targets (B, bins) or (B,);
    a lookahead Depth-Q-Net's: actions (B, K), targets (B, K, bins) (NaN on masked steps).
    `next_inputs`: the next frame's features (B, D), for a bootstrapped target; `current`: the
    frame's own bins (B, bins; invalid as the clip), for a "depth_first" head; else None."""

    inputs: torch.Tensor
    actions: torch.Tensor
    targets: torch.Tensor
    next_inputs: torch.Tensor | None = None
    current: torch.Tensor | None = None

    def to(self, device: torch.device) -> Batch:
        """The batch on `device` (a no-op on the CPU, where samples live)."""
        def move(t: torch.Tensor | None) -> torch.Tensor | None:
            return None if t is None else t.to(device)

        return Batch(self.inputs.to(device), self.actions.to(device), self.targets.to(device),
                     move(self.next_inputs), move(self.current))


class Samples(ABC):
    """The samples of a view; `draw` picks batch indices, `batch` builds one, `predict` runs the model,
    `trunk_features` the part before the head."""

    def __init__(self, arrays: dict[str, np.ndarray]) -> None:
        self.run_offsets = arrays["run_offsets"]
        self.actions = torch.from_numpy(arrays["action"]).float()
        self.targets = torch.from_numpy(arrays["target"]).float()
        # a "depth_first" head's perception target: the frame's own bins, an invalid one as the clip
        current = arrays.get("current")
        self.current = (None if current is None
                        else torch.from_numpy(np.nan_to_num(current, nan=DEPTH_CLIP)).float())

    def draw(self, n: int, rng: np.random.Generator) -> torch.Tensor:
        return torch.from_numpy(run_then_frame(self.run_offsets, n, rng))

    @abstractmethod
    def batch(self, idx: torch.Tensor) -> Batch: ...

    @abstractmethod
    def predict(self, model: QNet, batch: Batch) -> torch.Tensor: ...

    @abstractmethod
    def trunk_features(self, model: QNet, batch: Batch) -> torch.Tensor:
        """The trunk features of the batch's frames (cached, or the trunk run on them)."""


class FeatureSamples(Samples):
    """Samples whose trunk features are cached: the head is all that runs. With `following`, each
    batch carries its samples' next frames' features too (a one-step sample's next frame always exists).

    With a `mirrored` table (the features of the frames flipped left to right), each drawn sample is
    taken mirrored with probability 1/2 (docs/design.md#mirror): its mirrored features, its action
    negated, its depth bins reversed (left is right); a collision target stays as it is.
    """

    def __init__(
        self, arrays: dict[str, np.ndarray], table: FeatureTable, split: str, following: bool = False,
        mirrored: FeatureTable | None = None,
    ) -> None:
        super().__init__(arrays)
        following_rows = {**arrays, "frame_id": arrays["frame_id"] + 1}
        tables = (table,) if mirrored is None else (table, mirrored)
        self.features = self._gather(tables, split, arrays)  # [m, i]: sample i's features, m: mirrored
        self.following = self._gather(tables, split, following_rows) if following else None
        self.targets = torch.stack([self.targets, self.targets.flip(-1) if self.targets.ndim > 1
                                    else self.targets])[: len(tables)]
        if self.current is not None:
            self.current = torch.stack([self.current, self.current.flip(-1)])[: len(tables)]
        self.actions = torch.stack([self.actions, -self.actions])[: len(tables)]

    def draw(self, n: int, rng: np.random.Generator) -> torch.Tensor:
        """(n, 2) rows: the sample and whether it is taken mirrored (never without a mirrored table)."""
        idx = super().draw(n, rng)
        mirror = rng.random(n) < 0.5 if len(self.features) == 2 else np.zeros(n, dtype=bool)
        return torch.stack([idx, torch.from_numpy(mirror.astype(np.int64))], dim=1)

    def batch(self, idx: torch.Tensor) -> Batch:
        i, m = idx[:, 0], idx[:, 1]
        following = None if self.following is None else self.following[m, i].float()
        current = None if self.current is None else self.current[m, i]
        return Batch(self.features[m, i].float(), self.actions[m, i], self.targets[m, i], following, current)

    def predict(self, model: QNet, batch: Batch) -> torch.Tensor:
        return model.head(batch.inputs, batch.actions)

    def trunk_features(self, model: QNet, batch: Batch) -> torch.Tensor:
        return batch.inputs

    @staticmethod
    def _gather(
        tables: tuple[FeatureTable, ...], split: str, arrays: dict[str, np.ndarray]
    ) -> torch.Tensor | MappedRows:
        """The samples' rows of each table, in memory: (len(tables), S, D)."""
        return _stack([t.gather(split, arrays) for t in tables])


class ActivationSamples(FeatureSamples):
    """Samples of a trunk tuned from cached activations (docs/design.md#tuned-trunk): its frozen early
    stages' map per frame (`depthq.train.features.load_activations`), read batch by batch from the
    memory-mapped cache (at 7168 numbers a frame, 500 runs' frames would take ≈ 0.5 GB of memory per
    table); the late stages and the head run on it. Mirrored as `FeatureSamples` are, from the
    activations of the flipped frames: the early stages' stride-2 convolutions pad one side only
    (TensorFlow's "SAME"), so flipping a frame's cached map is not the map of the flipped frame."""

    def predict(self, model: QNet, batch: Batch) -> torch.Tensor:
        return model.head(self.trunk_features(model, batch), batch.actions)

    def trunk_features(self, model: QNet, batch: Batch) -> torch.Tensor:
        return model.trunk.late_features(batch.inputs)

    @staticmethod
    def _gather(
        tables: tuple[FeatureTable, ...], split: str, arrays: dict[str, np.ndarray]
    ) -> torch.Tensor | MappedRows:
        rows = [t.rows(split, arrays["run_id"], arrays["frame_id"]) for t in tables]
        return MappedRows(tables, np.stack(rows))


class MappedRows:
    """Rows of memory-mapped tables read on demand: `[m, i]` is sample i's row of table m[i], as one
    float16 tensor (B, D)."""

    def __init__(self, tables: tuple[FeatureTable, ...], rows: np.ndarray) -> None:
        self.arrays = [t.features for t in tables]
        self.rows = rows  # (len(tables), S)

    def __len__(self) -> int:
        """The tables, as a stacked tensor's first axis counts them."""
        return len(self.arrays)

    def __getitem__(self, key: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
        m, i = (k.numpy() for k in key)
        out = np.empty((len(i), self.arrays[0].shape[1]), dtype=np.float16)
        for table, array in enumerate(self.arrays):
            taken = m == table
            if taken.any():
                out[taken] = array[self.rows[table, i[taken]]]
        return torch.from_numpy(out)


def _stack(tensors: list[torch.Tensor]) -> torch.Tensor:
    """(len, …): one tensor as a view (no copy of a large feature table), two stacked."""
    return tensors[0][None] if len(tensors) == 1 else torch.stack(tensors)


class ImageSamples(Samples):
    """Samples as frames, decoded and resized once and held as uint8: the trunk runs (and learns) too.

    Decoding a JPEG costs more than a small trunk's training step on a GPU, and every frame is drawn
    many times, so the frames are decoded once (S × 3 × size² bytes: ≈ 1.3 GB for 500 runs at 128 px).
    Resized and scaled by `preprocess`'s own two steps, so a batch is bit-equal to preprocessing its frames.
    """

    def __init__(self, view: FrameView, size: int, progress: bool = False) -> None:
        super().__init__(view.arrays)
        self.frames = torch.empty((len(view), 3, size, size), dtype=torch.uint8)
        chunk = 256
        for start in Bar(range(0, len(view), chunk), desc="decode frames", unit="chunk",
                          disable=not progress):
            stop = min(start + chunk, len(view))
            self.frames[start:stop] = resize_frames(np.stack([view[i][0] for i in range(start, stop)]), size)

    def batch(self, idx: torch.Tensor) -> Batch:
        current = None if self.current is None else self.current[idx]
        return Batch(scale_frames(self.frames[idx]), self.actions[idx], self.targets[idx], current=current)

    def predict(self, model: QNet, batch: Batch) -> torch.Tensor:
        return model(batch.inputs, batch.actions)

    def trunk_features(self, model: QNet, batch: Batch) -> torch.Tensor:
        return model.trunk(batch.inputs)
