"""The feature cache: a frozen trunk is a fixed function, so its features are computed once per
(dataset, trunk, input size) and every training run after that only trains the head.

Layout, inside the dataset folder:

    DIR/features/<trunk>_<size>/features.f16.npy   float16 (frames, feature_dim), memory-mapped;
                                                   every frame of every run, train then val, in
                                                   manifest order
    DIR/features/<trunk>_<size>/index.json          written last: the cache is complete only when it
                                                   exists and matches (format, trunk, input_size,
                                                   fingerprint, shape, bytes, package version);
                                                   `sha256`: the array's, checked whenever it is
                                                   read; `host`: the machine and threads that
                                                   computed it

index.json: `runs` maps a run name (e.g. "train_000012") to [first row, n_frames]; `fingerprint`
is the SHA-256 of the manifest's (split, index, file sha256) rows, so adding, removing or
rewriting a run invalidates the cache. A recompute first deletes index.json, writes the array to
a temporary sibling and renames it into place, then writes index.json: an interrupted
computation is never read as complete (it starts over on the next call, which removes the
temporary array a killed one left). A cache without `sha256` (an older depthq's) is computed again;
one whose array does not match it is a DataError (delete the folder to compute it afresh).

float16 keeps the cache at half the size; EfficientNet-Lite0 features are averages of activations
of magnitude < 10, so rounding errs by at most 2⁻¹¹ relative (< 0.005 absolute).

A trunk tuned from cached activations (`TrainConfig.tune_stages`, docs/design.md#tuned-trunk) reads
the activation cache of its frozen early stages (`load_activations`): the same layout, format and
checks, the early stages' flattened map as each frame's row, in DIR/features/<early trunk>_<size>/
(`depthq.blocks.trunk.early_trunk_name`: efficientnet_lite0_stage5_128 for a trunk tuning its last 2
stages, 7168 numbers a frame).
"""

from __future__ import annotations

import os
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from depthq.blocks.trunk import (
    STAGES,
    Trunk,
    build_early_trunk,
    build_trunk,
    early_map_shape,
    early_trunk_name,
    preprocess,
    trunk_spec,
)
from depthq.checksum import file_sha256
from depthq.configio import provenance, read_json, write_json
from depthq.data.manifest import Dataset, RunEntry
from depthq.errors import ConfigError, DataError
from depthq.host import host_fingerprint
from depthq.parallel import cores
from depthq.progress import Bar

FEATURES = "features"
ARRAY = "features.f16.npy"
INDEX = "index.json"
SHA256 = "sha256"  # index.json's checksum of the array's bytes, checked whenever the cache is read
FORMAT = "depthq-features"
FORMAT_VERSION = 1
BATCH = 128  # frames per decode + trunk batch (the trunk splits it into cache-sized micro-batches)


def cache_dir(root: Path, trunk: str, size: int, mirrored: bool = False) -> Path:
    """Where the features of `trunk` at `size` px for the dataset in `root` live (`mirrored`: those of
    every frame flipped left to right, for a training with mirrored samples)."""
    return Path(root) / FEATURES / f"{trunk}_{size}{'_mirrored' if mirrored else ''}"


@dataclass(frozen=True)
class FeatureTable:
    """Trunk features of every frame of a dataset; `computed` says whether this call made them."""

    features: np.ndarray  # (frames, feature_dim) float16, memory-mapped read-only
    runs: dict[str, tuple[int, int]]  # run name -> (first row, n_frames)
    computed: bool

    def rows(self, split: str, run_ids: np.ndarray, frame_ids: np.ndarray) -> np.ndarray:
        """Rows of the samples (split index of the run, frame) that `view_arrays` lists."""
        first = {index: self.runs[f"{split}_{index:06d}"][0] for index in np.unique(run_ids).tolist()}
        return np.array([first[r] for r in run_ids.tolist()], dtype=np.int64) + frame_ids

    def gather(self, split: str, arrays: dict[str, np.ndarray]) -> torch.Tensor:
        """The features of a view's samples, in its order, as one contiguous float16 tensor in memory."""
        return torch.from_numpy(self.features[self.rows(split, arrays["run_id"], arrays["frame_id"])])


def load_features(
    dataset: Dataset, trunk: str, size: int, progress: bool = True, device: torch.device | str = "cpu",
    mirrored: bool = False,
) -> FeatureTable:
    """The cached features of `dataset` (`mirrored`: of its frames flipped left to right), computed
    first (on `device`) if missing or stale."""
    if not trunk_spec(trunk).frozen:
        raise ConfigError(f"trunk {trunk!r} is trained with the head: no feature cache")
    return _load(dataset, trunk, trunk_spec(trunk).feature_dim, lambda: build_trunk(trunk), size, progress,
                 device, mirrored)


def load_activations(
    dataset: Dataset, tune_stages: int, size: int, progress: bool = True, device: torch.device | str = "cpu",
    mirrored: bool = False,
) -> FeatureTable:
    """The cached map of the frozen early stages of a trunk whose last `tune_stages` stages are tuned
    (`depthq.blocks.trunk.build_early_trunk`), one flattened row per frame, computed first if missing or
    stale; as `load_features` otherwise."""
    frozen = STAGES - tune_stages
    channels, side, _ = early_map_shape(frozen, size)
    return _load(dataset, early_trunk_name(frozen), channels * side * side,
                 lambda: build_early_trunk(frozen, size), size, progress, device, mirrored)


def _load(
    dataset: Dataset, trunk: str, feature_dim: int, build: Callable[[], Trunk], size: int, progress: bool,
    device: torch.device | str, mirrored: bool,
) -> FeatureTable:
    """The cache of the frozen trunk `build` makes (`trunk`, giving `feature_dim` numbers a frame)."""
    folder = cache_dir(dataset.root, trunk, size, mirrored)
    expected = _index(dataset, trunk, feature_dim, size, mirrored)
    table = _read(folder, expected)
    if table is not None:
        return table
    compute_features(dataset, build().to(device), size, folder, expected, progress)
    table = _read(folder, expected)
    if table is None:
        raise DataError(f"{folder}: feature cache just written does not read back")
    return FeatureTable(table.features, table.runs, computed=True)


def trunk_threads() -> int:
    """Threads for the trunk: every core. (Leaving one core to the JPEG-decoding thread was no faster
    on the 2-core reference machine: 333 frames/s end to end either way.)"""
    return cores()


def features_ready(dataset: Dataset, trunk: str, size: int) -> bool:
    """Whether a valid cache of `dataset` for (trunk, size) is on disk."""
    expected = _index(dataset, trunk, trunk_spec(trunk).feature_dim, size)
    return _read(cache_dir(dataset.root, trunk, size), expected) is not None


def compute_features(
    dataset: Dataset, trunk: Trunk, size: int, folder: Path, index: dict, progress: bool = True
) -> float:
    """Write the cache of `index` into `folder` (see the module docstring); returns frames/s end to end."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / INDEX).unlink(missing_ok=True)  # from here on the folder is incomplete
    remove_stale(folder)
    n_frames = sum(n for _, n in index["runs"].values())
    tmp = folder / f".{ARRAY}.{os.getpid()}.tmp"
    torch.set_num_threads(trunk_threads())
    device = next(trunk.parameters()).device
    start = time.perf_counter()
    try:
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float16, shape=(n_frames, trunk.feature_dim))
        bar = Bar(total=n_frames, desc=f"features {trunk.name} {size}px", unit="frame", disable=not progress)
        row = 0
        with torch.inference_mode():
            for batch in prefetch(frame_batches(dataset, size, index.get("mirrored", False)), depth=2):
                out[row : row + len(batch)] = trunk(batch.to(device)).cpu().numpy()
                row += len(batch)
                bar.update(len(batch))
        bar.close()
        if row != n_frames:
            raise DataError(f"{dataset.root}: decoded {row} frames, manifest says {n_frames}")
        out.flush()
        del out
        os.replace(tmp, folder / ARRAY)
    finally:
        tmp.unlink(missing_ok=True)
    seconds = time.perf_counter() - start
    path = folder / ARRAY
    # The machine and threads that computed them, recorded but not checked: a cache copied from
    # another host is used as it is (its last bits may differ from this host's, docs/design.md#determinism).
    write_json(folder / INDEX, {**index, "host": host_fingerprint(), "bytes": path.stat().st_size,
                                SHA256: file_sha256(path), "seconds": round(seconds, 2)})
    return n_frames / seconds


def verify_caches(dataset: Dataset) -> list[str]:
    """One message per feature cache of `dataset` whose array does not match the SHA-256 its index
    records (`depthq dataset verify`); a stale or unchecked cache is no problem: it is computed again."""
    problems = []
    for index_path in sorted((dataset.root / FEATURES).glob(f"*/{INDEX}")):
        try:
            recorded = read_json(index_path).get(SHA256)
        except (DataError, AttributeError) as err:
            problems.append(f"{index_path}: unreadable ({err}); delete {index_path.parent}")
            continue
        array = index_path.parent / ARRAY
        if recorded is not None and (not array.is_file() or file_sha256(array) != recorded):
            problems.append(f"{array}: corrupted feature cache (its SHA-256 is not the one {INDEX} "
                            f"records); delete {index_path.parent}: the next training computes it afresh")
    return problems


def remove_stale(folder: Path) -> None:
    """Remove the temporary arrays of computations whose process is gone (killed): their PID is in
    the name, and a live one (another training computing the same cache) is left alone."""
    for tmp in folder.glob(f".{ARRAY}.*.tmp"):
        pid = tmp.name.removeprefix(f".{ARRAY}.").removesuffix(".tmp")
        if not pid.isdigit() or not _alive(int(pid)):
            tmp.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _index(dataset: Dataset, trunk: str, feature_dim: int, size: int, mirrored: bool = False) -> dict:
    """What index.json must say for the cache to be valid (minus the file's size)."""
    runs, row = {}, 0
    for entry in dataset.entries():
        runs[entry.name] = [row, entry.n_frames]
        row += entry.n_frames
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "provenance": provenance(),
        "trunk": trunk,
        "input_size": size,
        "fingerprint": dataset.fingerprint(),
        "runs": runs,
        "shape": [row, feature_dim],
        **({"mirrored": True} if mirrored else {}),
    }


def _read(folder: Path, expected: dict) -> FeatureTable | None:
    """The cache in `folder` if complete and made for `expected`, else None (stale or interrupted)."""
    try:
        index = read_json(folder / INDEX)
    except (FileNotFoundError, DataError):
        return None
    if not isinstance(index, dict) or any(index.get(key) != value for key, value in expected.items()):
        return None
    path = folder / ARRAY
    if not path.is_file() or path.stat().st_size != index.get("bytes"):
        return None
    try:
        features = np.load(path, mmap_mode="r")
    except ValueError:
        return None
    if features.dtype != np.float16 or list(features.shape) != expected["shape"]:
        return None
    if SHA256 not in index:
        return None  # written before the cache had a checksum: computed again
    if file_sha256(path) != index[SHA256]:
        raise DataError(f"{path}: corrupted feature cache (its SHA-256 is not the one {INDEX} records); "
                        f"delete {folder} and run again: the cache is computed afresh")
    runs = {name: (int(first), int(n)) for name, (first, n) in index["runs"].items()}
    return FeatureTable(features, runs, computed=False)


def frame_batches(dataset: Dataset, size: int, mirrored: bool = False) -> Iterator[torch.Tensor]:
    """Every frame of every run in manifest order, decoded and resized (`mirrored`: then flipped left to
    right), in batches of `BATCH`."""
    frames: list[np.ndarray] = []
    for entry in dataset.entries():
        for image in _run_frames(dataset, entry):
            frames.append(image)
            if len(frames) == BATCH:
                yield _prepare(frames, size, mirrored)
                frames = []
    if frames:
        yield _prepare(frames, size, mirrored)


def _prepare(frames: list[np.ndarray], size: int, mirrored: bool) -> torch.Tensor:
    batch = preprocess(np.stack(frames), size)
    return batch.flip(-1) if mirrored else batch


def _run_frames(dataset: Dataset, entry: RunEntry) -> Iterator[np.ndarray]:
    with dataset.reader(entry) as reader:
        for t in range(entry.n_frames):
            yield reader.image(t)


def prefetch(batches: Iterator[torch.Tensor], depth: int) -> Iterator[torch.Tensor]:
    """Run `batches` in a background thread, `depth` ahead: JPEG decoding and resizing release the
    GIL, so they overlap the trunk on the other core. Errors are raised in the caller's thread."""
    q: queue.Queue = queue.Queue(maxsize=depth)
    done = object()
    stop = threading.Event()

    def produce() -> None:
        try:
            for batch in batches:
                if stop.is_set():
                    return
                q.put(batch)
            q.put(done)
        except BaseException as err:  # handed to the consumer
            q.put(err)

    thread = threading.Thread(target=produce, daemon=True)
    thread.start()
    try:
        while (item := q.get()) is not done:
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        while thread.is_alive():  # unblock a producer waiting on a full queue
            try:
                q.get_nowait()
            except queue.Empty:
                thread.join(0.01)
