"""The training views of a dataset: samples as arrays (for cached features) and as a PyTorch dataset.

A view is the sample list of one split (or nested subset) for one target (`depthq.data.samples.Target`,
a function of a run; each network declares its own: `depthq.networks.Network.target`), e.g.:

    bins_target         (image_t, a_t, bins[t + 1])   Depth-Q-Net's; collision runs lose their last H samples
    collision_target    (image_t, a_t, y_t)           Coll-Q-Net's; every frame with an action

A bins view's bins (its targets and the frame's own `current` bins) are the LiDAR's, or with
`labels="camera"` those a labeller estimated from the camera (`depthq.data.camera_labels`).
A bins view with `lookahead` K > 1 has the same samples, each with K actions and K targets
(a_t … a_{t+K−1}, bins[t + 1] … bins[t + K]) and a mask of the valid steps (`depthq.data.samples`).

`view_arrays` gives everything but the images as NumPy arrays, samples ordered by run then frame,
with `run_offsets` so that "a random run, then a random frame of it" (docs/design.md#sampling) can be drawn on
precomputed trunk features as well (`run_then_frame`). `FrameView` adds the images,
decoded on demand from run files opened lazily (a bounded number per process, reopened after a
fork), so a 900-run dataset never sits in memory. Draw their batches with `view.sampler(...)`.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Iterator
from typing import Any

import numpy as np
from torch.utils.data import Dataset as TorchDataset
from torch.utils.data import Sampler

from depthq.data.camera_labels import LABEL_SOURCES, missing_labels_message
from depthq.data.manifest import Dataset, RunEntry
from depthq.data.run import Run
from depthq.data.runfile import RunReader
from depthq.data.samples import SampleConfig, Target, ends_in_collision
from depthq.data.subsets import select_runs
from depthq.errors import ConfigError


def view_arrays(
    dataset: Dataset,
    split: str,
    n_runs: int | None,
    target: Target,
    config: SampleConfig | None = None,
    lookahead: int = 1,
    labels: str = "lidar",
) -> dict[str, np.ndarray]:
    """All samples of a view of `target`, run by run; the bins it reads from `labels` (the LiDAR or the
    camera).

    Keys: `run_index` (R,) split index of each run; `run_offsets` (R + 1,) samples of run r are
    `run_offsets[r]:run_offsets[r + 1]`; per sample (S,): `run_id` (split index of its run),
    `frame_id` (t), `action` (a_t: the stored command of frame t − action_lag, clipped to
    ±action_clip), `current`: bins[t] (S, 26), and `target`: the target's, e.g. bins[t + 1] (S, 26)
    for `bins_target`, y_t (S,) for `collision_target`.

    A target of `lookahead` K > 1 steps (`bins_target`'s): `action` (S, K) the commands of frames
    t … t + K − 1 (lag and clip as above), `target` (S, K, 26) bins[t + 1] … bins[t + K], NaN in every
    bin of a masked step (so no loss counts it), and `mask` (S, K) the valid steps (`depthq.data.samples`).
    """
    if isinstance(lookahead, bool) or not isinstance(lookahead, int) or lookahead < 1:
        raise ConfigError(f"view lookahead must be an integer >= 1, got {lookahead!r}")
    if labels not in LABEL_SOURCES:
        raise ConfigError(f"view labels must be one of {LABEL_SOURCES}, got {labels!r}")
    config = config or SampleConfig()
    runs = select_runs(dataset, split, n_runs, config.min_frames)
    if not runs:
        raise ConfigError(f"{dataset.root} has no usable {split} runs (at least {config.min_frames} frames)")
    frame_ids, actions, targets, masks, current = [], [], [], [], []
    for entry in runs:
        run = dataset.read_run(entry, images=False)
        bins = _depth_bins(dataset, run, labels)
        got = target(bins, ends_in_collision(entry, config.every_run_end), config, lookahead)
        if got.mask is not None:
            masks.append(got.mask)
        frame_ids.append(got.frames)
        current.append(bins[got.frames])
        actions.append(np.clip(run.actions[got.commands], -config.action_clip, config.action_clip))
        targets.append(got.targets)
    counts = np.array([len(t) for t in frame_ids], dtype=np.int64)
    run_index = np.array([entry.index for entry in runs], dtype=np.int64)
    return {
        "run_index": run_index,
        "run_offsets": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        "run_id": np.repeat(run_index, counts),
        "frame_id": np.concatenate(frame_ids),
        "action": np.concatenate(actions),
        "target": np.concatenate(targets),
        "current": np.concatenate(current),
        **({"mask": np.concatenate(masks)} if masks else {}),
    }


def _depth_bins(dataset: Dataset, run: Run, labels: str) -> np.ndarray:
    """The run's bins from `labels`: the LiDAR's, or the camera's (a ConfigError saying how to write them
    when the run holds none)."""
    if labels == "lidar":
        return run.bins
    if run.camera is None:
        raise ConfigError(missing_labels_message(dataset.root, run.meta.name))
    return run.camera.bins


def run_then_frame(run_offsets: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """`n` sample indices, each from a uniformly random run, then a uniformly random sample of that run.

    Short runs are drawn as often as long ones (docs/design.md#sampling), so a sample of a short run
    weighs more.
    """
    runs = rng.integers(len(run_offsets) - 1, size=n)
    starts = run_offsets[runs]
    return starts + rng.integers(0, run_offsets[runs + 1] - starts)


class RunThenFrameSampler(Sampler[int]):
    """DataLoader indices by `run_then_frame`; each pass draws new ones from one seeded stream."""

    def __init__(self, run_offsets: np.ndarray, num_samples: int, seed: int) -> None:
        self.run_offsets = run_offsets
        self.num_samples = num_samples
        self._rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return self.num_samples

    def __iter__(self) -> Iterator[int]:
        return iter(run_then_frame(self.run_offsets, self.num_samples, self._rng).tolist())


class FrameView(TorchDataset):
    """Map-style dataset of a view's samples (`view_arrays` of `split`): item i is (image uint8
    (H, W, 3), action, target), float32 (a lookahead view's: actions (K,), targets (K, 26))."""

    def __init__(
        self, dataset: Dataset, split: str, arrays: dict[str, np.ndarray], max_open_files: int = 64
    ) -> None:
        self.dataset = dataset
        self.arrays = arrays
        self._entries: dict[int, RunEntry] = {entry.index: entry for entry in dataset.entries(split)}
        self._max_open = max_open_files
        self._readers: OrderedDict[int, RunReader] = OrderedDict()
        self._pid = os.getpid()

    def __len__(self) -> int:
        return len(self.arrays["frame_id"])

    def __getitem__(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        run_id = int(self.arrays["run_id"][i])
        image = self._reader(run_id).image(int(self.arrays["frame_id"][i]))
        return image, self.arrays["action"][i], self.arrays["target"][i]

    def sampler(self, num_samples: int, seed: int) -> RunThenFrameSampler:
        """Random run, then random frame (docs/design.md#sampling), reproducible from `seed`."""
        return RunThenFrameSampler(self.arrays["run_offsets"], num_samples, seed)

    def _reader(self, run_id: int) -> RunReader:
        """The run's open file; at most `max_open_files` stay open, least recently used closed first."""
        if self._pid != os.getpid():  # a forked DataLoader worker: the parent's HDF5 handles are not ours
            self._readers, self._pid = OrderedDict(), os.getpid()
        reader = self._readers.pop(run_id, None)
        if reader is None:
            reader = self.dataset.reader(self._entries[run_id])
            if len(self._readers) >= self._max_open:
                self._readers.popitem(last=False)[1].close()
        self._readers[run_id] = reader
        return reader

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_readers"] = OrderedDict()  # open files do not travel to worker processes
        return state

