"""The paper's nested training subsets: "the first n usable training runs" (docs/design.md#subsets, Table II).

n counts usable runs (at least `min_frames` frames), so a subset of 50 trains on 50 runs, and the
subset of 50 is the start of the subset of 100, and so on. Runs are taken in index order and only
up to the first index that is not in the dataset yet: parallel collectors finish out of order, and
a subset must not depend on which of them happened to be done. Validation runs are their own
split; a view of them uses all usable ones. n counts collected runs: a selected run brings its
re-renders in other looks along (`depthq.data.rerender`), so K looks train on n runs' poses in K + 1 looks.
"""

from __future__ import annotations

from depthq.data.manifest import Dataset, RunEntry
from depthq.data.samples import usable
from depthq.errors import ConfigError

PAPER_SUBSETS = (50, 100, 200, 500, 700, 900)


def usable_runs(dataset: Dataset, split: str, min_frames: int) -> list[RunEntry]:
    """The split's usable collected runs in index order, from index 0 up to the first missing index
    (re-rendered runs are not among them)."""
    runs = []
    collected = [entry for entry in dataset.entries(split) if entry.rendered is None]
    for expected, entry in enumerate(collected):
        if entry.index != expected:
            break
        if usable(entry, min_frames):
            runs.append(entry)
    return runs


def select_runs(dataset: Dataset, split: str, n_runs: int | None, min_frames: int) -> list[RunEntry]:
    """The first `n_runs` usable collected runs of `split` (all of them for None) and their re-renders;
    ConfigError if there are fewer."""
    runs = usable_runs(dataset, split, min_frames)
    if n_runs is None:
        return with_renders(dataset, split, runs)
    if n_runs < 1:
        raise ConfigError(f"a subset needs at least one run, got n_runs={n_runs}")
    if n_runs > len(runs):
        collected = sum(entry.rendered is None for entry in dataset.entries(split))
        raise ConfigError(
            f"subset of n_runs={n_runs} {split} runs requested, but {dataset.root} has only "
            f"{len(runs)} usable {split} runs (of {collected} collected; runs under {min_frames} frames are "
            "left out)"
        )
    return with_renders(dataset, split, runs[:n_runs])


def first_runs(dataset: Dataset, split: str, n_runs: int, every_look: bool) -> list[RunEntry]:
    """The first `n_runs` collected runs of `split` (usable or not), with their re-renders if
    `every_look`: a labeller's pool."""
    collected = [entry for entry in dataset.entries(split) if entry.rendered is None][:n_runs]
    return with_renders(dataset, split, collected) if every_look else collected


def with_renders(dataset: Dataset, split: str, runs: list[RunEntry]) -> list[RunEntry]:
    """`runs` and, after them, every re-render of one of them in another look, in index order."""
    chosen = {entry.index for entry in runs}
    return runs + [entry for entry in dataset.entries(split)
                   if entry.rendered is not None and entry.rendered.source in chosen]
