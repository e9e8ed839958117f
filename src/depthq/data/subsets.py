"""The paper's nested training subsets: "the first n usable training runs" (docs/design.md#subsets, Table II).

n counts usable runs (at least `min_frames` frames), so a subset of 50 trains on 50 runs, and the
subset of 50 is the start of the subset of 100, and so on. Runs are taken in index order and only
up to the first index that is not in the dataset yet: parallel collectors finish out of order, and
a subset must not depend on which of them happened to be done. Validation runs are their own
split; a view of them uses all usable ones.
"""

from __future__ import annotations

from depthq.data.manifest import Dataset, RunEntry
from depthq.data.samples import usable
from depthq.errors import ConfigError

PAPER_SUBSETS = (50, 100, 200, 500, 700, 900)


def usable_runs(dataset: Dataset, split: str, min_frames: int) -> list[RunEntry]:
    """The split's usable runs in index order, from index 0 up to the first missing index."""
    runs = []
    for expected, entry in enumerate(dataset.entries(split)):
        if entry.index != expected:
            break
        if usable(entry, min_frames):
            runs.append(entry)
    return runs


def select_runs(dataset: Dataset, split: str, n_runs: int | None, min_frames: int) -> list[RunEntry]:
    """The first `n_runs` usable runs of `split` (all of them for None); ConfigError if there are fewer."""
    runs = usable_runs(dataset, split, min_frames)
    if n_runs is None:
        return runs
    if n_runs < 1:
        raise ConfigError(f"a subset needs at least one run, got n_runs={n_runs}")
    if n_runs > len(runs):
        raise ConfigError(
            f"subset of n_runs={n_runs} {split} runs requested, but {dataset.root} has only "
            f"{len(runs)} usable {split} runs (of {len(dataset.entries(split))} collected; "
            f"runs under {min_frames} frames are left out)"
        )
    return runs[:n_runs]
