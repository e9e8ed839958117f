"""The storage layer on synthetic runs written to disk and read back: targets, subsets, files, views."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from depthq.cli import main
from depthq.data import DataConfig
from depthq.data import runfile as runfile_module
from depthq.data.manifest import MANIFEST, Dataset
from depthq.data.run import Run, RunMeta
from depthq.data.runfile import JPEG_MAX_MEAN_ABS_ERROR, RunReader, read_frame, read_run, write_run
from depthq.data.samples import (
    bins_target,
    coll_sample_indices,
    collision_target,
    collision_targets,
    depth_sample_indices,
    usable,
)
from depthq.data.stats import dataset_stats
from depthq.data.subsets import select_runs
from depthq.data.views import FrameView, run_then_frame, view_arrays
from depthq.errors import ConfigError, DataError

SMALL = (24, 32)  # image size for tests that do not look at JPEG quality
CONFIG = DataConfig(horizon=5, min_frames=20, subsets=(2, 4))


def canyon_image(rng: np.random.Generator, shape: tuple[int, int] = (308, 410)) -> np.ndarray:
    """A frame like the simulator's: shaded grey walls, a floor gradient, σ = 0.007·255 pixel noise."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    horizon = h * rng.uniform(0.45, 0.55)
    floor = y > horizon + 0.13 * h * np.abs(x - w / 2) / (w / 2)
    seams = np.sort(rng.uniform(0, w, 8))
    wall = np.interp(x[0], np.r_[0, seams, w], rng.uniform(90, 200, 10))[None, :].repeat(h, 0)
    grey = np.where(floor, 100 + 60 * (y - horizon) / (h - horizon), np.where(y < 0.16 * h, 178, wall))
    noisy = grey[..., None] + rng.normal(0, 0.007 * 255, (h, w, 3))
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def make_run(
    split: str,
    index: int,
    n_frames: int,
    end_reason: str = "bump",
    shape: tuple[int, int] = SMALL,
    seed: int = 0,
) -> Run:
    """A run whose arrays encode (run, frame), so a wrong target or frame shows up in the tests."""
    rng = np.random.default_rng([seed, index, split == "val"])
    t = np.arange(n_frames, dtype=np.float32)
    actions = rng.uniform(-1, 1, n_frames).astype(np.float32)
    actions[-1] = np.nan
    bins = (index * 1000 + t[:, None] + np.arange(26, dtype=np.float32) / 100).astype(np.float32)
    bins[::3, 7] = np.nan
    scans = rng.uniform(0.1, 3.5, (n_frames, 360)).astype(np.float32)
    scans[:, 180] = np.inf
    meta = RunMeta(split, index, "train", index, 1000 + index, 2000 + index, end_reason, n_frames)
    return Run(
        meta=meta,
        images=np.stack([canyon_image(rng, shape) for _ in range(n_frames)]),
        scans=scans,
        bins=bins,
        actions=actions,
        poses=rng.normal(size=(n_frames, 3)).astype(np.float32),
        times=t / 10,
    )


def make_dataset(root: Path, lengths: list[int], val_lengths: tuple[int, ...] = (22,)) -> Dataset:
    """Train runs of these lengths (every third ends at the time limit, the rest in a bump), val runs."""
    dataset = Dataset.create(root, {"collect": {"runs": len(lengths)}}, seed=7)
    for i, n in enumerate(lengths):
        dataset.add_run(make_run("train", i, n, "time_limit" if i % 3 == 2 else "bump"), jpeg_quality=90)
    for i, n in enumerate(val_lengths):
        dataset.add_run(make_run("val", i, n), jpeg_quality=90)
    return dataset


# --- targets ------------------------------------------------------------------------------------


def test_targets_of_a_collision_run() -> None:
    targets = collision_targets(25, True, horizon=5)
    assert targets.dtype == np.float32 and targets.shape == (24,)
    assert targets[:19].sum() == 0 and (targets[19:] == 1).all()
    np.testing.assert_array_equal(coll_sample_indices(25), np.arange(24))
    np.testing.assert_array_equal(depth_sample_indices(25, True, horizon=5), np.arange(19))


def test_targets_of_a_run_without_collision() -> None:
    assert collision_targets(25, False, horizon=5).sum() == 0
    np.testing.assert_array_equal(depth_sample_indices(25, False, horizon=5), np.arange(24))
    assert collision_targets(4, True, horizon=5).tolist() == [1, 1, 1]
    assert len(depth_sample_indices(4, True, horizon=5)) == 0


def test_short_runs_are_left_out(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "d", [21, 19, 20, 25], val_lengths=(19,))
    assert [usable(e, 20) for e in dataset.entries("train")] == [True, False, True, True]
    with pytest.raises(ConfigError, match="no usable val runs"):
        FrameView(dataset, "val", view_arrays(dataset, "val", None, bins_target, CONFIG))
    assert [e.index for e in select_runs(dataset, "train", None, 20)] == [0, 2, 3]
    arrays = view_arrays(dataset, "train", None, collision_target, CONFIG)
    assert arrays["run_index"].tolist() == [0, 2, 3]
    assert len(arrays["frame_id"]) == 20 + 19 + 24


def test_a_usable_run_keeps_a_depth_sample_in_what_is_stored_and_what_is_counted() -> None:
    """min_frames >= horizon + 2, one rule for a collection's StorageConfig (the default horizon, 5) and
    a training's SampleConfig (its own); each names its setting and the bad value."""
    from depthq.data import StorageConfig
    from depthq.data.samples import SampleConfig

    StorageConfig(min_frames=7), SampleConfig(horizon=3, min_frames=5)  # the least each allows
    with pytest.raises(ConfigError, match=r"^data\.min_frames must be an integer >= 7 .*, got 6$"):
        StorageConfig(min_frames=6)
    with pytest.raises(ConfigError, match=r"^data\.min_frames must be an integer >= 7 .*, got True$"):
        StorageConfig(min_frames=True)
    with pytest.raises(ConfigError, match=r"^min_frames must be an integer >= 5 .*, got 4$"):
        SampleConfig(horizon=3, min_frames=4)


# --- subsets ------------------------------------------------------------------------------------


def test_subsets_are_nested_and_count_usable_runs(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "d", [20, 10, 21, 22, 23, 24])
    two, four = (select_runs(dataset, "train", n, 20) for n in (2, 4))
    assert [e.index for e in two] == [0, 2] and [e.index for e in four] == [0, 2, 3, 4]
    assert four[:2] == two
    with pytest.raises(ConfigError, match=r"n_runs=6 .*only 5 usable train runs"):
        select_runs(dataset, "train", 6, 20)
    assert [e.split for e in select_runs(dataset, "val", None, 20)] == ["val"]


def test_subsets_stop_at_the_first_missing_run(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "d", [20, 20])
    dataset.add_run(make_run("train", 3, 20))  # run 2 not collected yet (a slower worker)
    assert [e.index for e in select_runs(dataset, "train", None, 20)] == [0, 1]


# --- run files ----------------------------------------------------------------------------------


def test_round_trip_and_jpeg_error(tmp_path: Path) -> None:
    run = make_run("train", 3, 20, shape=(308, 410))
    info = write_run(tmp_path / "a.h5", run)
    back = read_run(tmp_path / "a.h5", expected=info)
    assert back.meta == run.meta
    for name in ("scans", "bins", "actions", "poses", "times"):
        np.testing.assert_array_equal(getattr(back, name), getattr(run, name), err_msg=name)
        assert getattr(back, name).dtype == np.float32
    assert back.images.shape == run.images.shape and back.images.dtype == np.uint8
    error = np.abs(back.images.astype(np.int16) - run.images).mean()
    assert error <= JPEG_MAX_MEAN_ABS_ERROR
    with RunReader(tmp_path / "a.h5") as reader:
        kb_per_frame = reader._jpeg.shape[0] / 1000 / len(reader)
        np.testing.assert_array_equal(read_frame(reader, 7), back.images[7])
    assert kb_per_frame <= 40
    np.testing.assert_array_equal(read_frame(tmp_path / "a.h5", 19), back.images[19])
    assert read_run(tmp_path / "a.h5", images=False).images is None
    assert write_run(tmp_path / "b.h5", run) == info  # same run, same bytes


def test_write_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = make_run("train", 0, 20)
    path = tmp_path / "runs" / "train_000000.h5"
    info = write_run(path, run)
    encode, calls = runfile_module.encode_jpeg, []

    def failing_encode(image: np.ndarray, quality: int) -> bytes:
        calls.append(1)
        if len(calls) > 3:
            raise KeyboardInterrupt  # the collector stopped halfway through a write
        return encode(image, quality)

    monkeypatch.setattr(runfile_module, "encode_jpeg", failing_encode)
    with pytest.raises(KeyboardInterrupt):
        write_run(path, make_run("train", 0, 20, seed=1))
    with pytest.raises(KeyboardInterrupt):
        write_run(tmp_path / "runs" / "train_000001.h5", run)
    assert sorted(p.name for p in path.parent.iterdir()) == ["train_000000.h5"]  # no temporary left behind
    assert read_run(path, expected=info).meta == run.meta  # the old file is untouched


def test_run_validation_names_the_bad_array() -> None:
    run = make_run("train", 0, 20)
    with pytest.raises(ValueError, match=r"bins must be float32"):
        Run(run.meta, run.images, run.scans, run.bins.astype(np.float64), run.actions, run.poses, run.times)
    with pytest.raises(ValueError, match=r"last, which is NaN"):
        Run(run.meta, run.images, run.scans, run.bins, np.zeros(20, np.float32), run.poses, run.times)


# --- manifest, corruption, verify ---------------------------------------------------------------


def _damage(dataset: Dataset) -> tuple[Path, Path]:
    truncated, flipped = (dataset.path(e) for e in dataset.entries("train")[:2])
    data = truncated.read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    data = bytearray(flipped.read_bytes())
    data[len(data) // 3] ^= 0x01  # one bit, inside the JPEG data
    flipped.write_bytes(bytes(data))
    return truncated, flipped


def test_verify_names_truncated_corrupted_missing_and_extra_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    dataset = make_dataset(tmp_path / "d", [20, 21, 22, 23])
    assert main(["dataset", "verify", str(tmp_path / "d")]) == 0
    assert "OK" in capsys.readouterr().out
    truncated, flipped = _damage(dataset)
    missing = dataset.path(dataset.entries("train")[2])
    missing.unlink()
    extra = tmp_path / "d" / "runs" / "train_000099.h5"
    extra.write_bytes(b"stray")
    assert main(["dataset", "verify", str(tmp_path / "d")]) == 1
    err = capsys.readouterr().err
    for path, word in (
        (truncated, "truncated"),
        (flipped, "corrupted"),
        (missing, "missing"),
        (extra, "extra"),
    ):
        assert f"{path}: {word}" in err
    assert str(dataset.path(dataset.entries("train")[3])) not in err


def test_verify_fails_on_fewer_runs_than_the_config_asks_for_or_none(
    small_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    partial = tmp_path / "partial"  # a partial copy: the first 3 runs, and a manifest listing them alone
    shutil.copytree(small_dataset, partial, ignore=shutil.ignore_patterns("features"))
    manifest = json.loads((partial / MANIFEST).read_text())
    for row in manifest["runs"][3:]:
        (partial / row["file"]).unlink()
    manifest["runs"] = manifest["runs"][:3]
    (partial / MANIFEST).write_text(json.dumps(manifest))
    assert main(["dataset", "verify", str(partial)]) == 1
    err = capsys.readouterr().err
    assert "of the 6 train runs, 2 of the 2 val runs its config asks for" in err and "OK" not in err
    assert main(["dataset", "verify", str(small_dataset)]) == 0  # the whole one
    capsys.readouterr()
    empty = tmp_path / "empty"  # what a collection that failed before its first run leaves
    Dataset.create(empty, Dataset.open(small_dataset).config, seed=0)
    assert main(["dataset", "verify", str(empty)]) == 1
    captured = capsys.readouterr()
    assert "holds no run" in captured.err and "OK" not in captured.out


def test_loading_a_damaged_file_raises(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "d", [20, 21, 22])
    truncated, flipped = _damage(dataset)
    entries = dataset.entries("train")
    with pytest.raises(DataError, match=f"{truncated}: truncated"):
        dataset.read_run(entries[0])
    with pytest.raises(DataError, match=f"{flipped}: corrupted"):
        dataset.reader(entries[1])
    with pytest.raises(DataError, match=str(truncated)):
        FrameView(dataset, "train", view_arrays(dataset, "train", 2, bins_target, CONFIG))
    with pytest.raises(DataError, match=f"{truncated}: not a readable HDF5"):
        read_run(truncated)  # without the manifest's hash, h5py's own error is still a DataError


def test_manifest_refuses_another_config(tmp_path: Path) -> None:
    root = tmp_path / "d"
    make_dataset(root, [20, 20])
    manifest = (root / MANIFEST).read_bytes()
    with pytest.raises(ConfigError, match=r"differs in: config\.collect\.runs, seed"):
        Dataset.create(root, {"collect": {"runs": 3}}, seed=8)
    assert (root / MANIFEST).read_bytes() == manifest  # refused without touching anything
    resumed = Dataset.create(root, {"collect": {"runs": 2}}, seed=7)
    assert len(resumed.entries()) == 3
    fresh = Dataset.create(root, {"collect": {"runs": 3}}, seed=8, overwrite=True)
    assert fresh.entries() == [] and list((root / "runs").iterdir()) == []
    assert json.loads((root / MANIFEST).read_text())["provenance"]["package"] == "depthq"


def test_open_names_a_missing_folder_or_manifest(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=f"{tmp_path / 'nope'}: no such dataset folder"):
        Dataset.open(tmp_path / "nope")
    with pytest.raises(ConfigError, match=f"{tmp_path}: not a dataset folder"):
        Dataset.open(tmp_path)
    assert main(["dataset", "stats", str(tmp_path / "nope")]) == 2


def test_same_runs_give_the_same_dataset_bytes(tmp_path: Path) -> None:
    a, b = make_dataset(tmp_path / "a", [20, 21]), make_dataset(tmp_path / "b", [20, 21])
    assert (a.root / MANIFEST).read_bytes() == (b.root / MANIFEST).read_bytes()
    assert [e.sha256 for e in a.entries()] == [e.sha256 for e in b.entries()]


# --- views and stats ----------------------------------------------------------------------------


def test_views_give_the_right_targets(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "d", [20, 24, 21])  # runs 0, 1 bump, run 2 time limit
    runs = {e.index: dataset.read_run(e) for e in dataset.entries("train")}
    depth = FrameView(dataset, "train", view_arrays(dataset, "train", 3, bins_target, CONFIG))
    assert len(depth) == 14 + 18 + 15  # the original drops the last 5 samples of every run
    for i in range(len(depth)):
        run_id, t = int(depth.arrays["run_id"][i]), int(depth.arrays["frame_id"][i])
        image, action, target = depth[i]
        np.testing.assert_array_equal(target, runs[run_id].bins[t + 1])
        assert action == runs[run_id].actions[t]
        np.testing.assert_array_equal(image, runs[run_id].images[t])
    coll = FrameView(dataset, "train", view_arrays(dataset, "train", 3, collision_target, CONFIG))
    assert len(coll) == 19 + 23 + 20
    targets = coll.arrays["target"]
    offsets = coll.arrays["run_offsets"]
    assert targets[offsets[0] : offsets[1]].tolist() == [0] * 14 + [1] * 5
    assert targets[offsets[2] : offsets[3]].tolist() == [0] * 15 + [1] * 5  # every run's end, as the original
    val = FrameView(dataset, "val", view_arrays(dataset, "val", None, bins_target, CONFIG))
    assert set(val.arrays["run_id"].tolist()) == {0} and len(val) == 16
    # Collision targets on bumps only: the time-limited run keeps all its samples, each 0.
    bumps_only = replace(CONFIG, every_run_end=False)
    assert len(view_arrays(dataset, "train", 3, bins_target, bumps_only)["frame_id"]) == 14 + 18 + 20
    coll = view_arrays(dataset, "train", 3, collision_target, bumps_only)
    assert coll["target"][coll["run_offsets"][2] :].sum() == 0


def test_actions_are_clipped_and_can_lag_one_frame(tmp_path: Path) -> None:
    """The stored command (up to ±2.84 rad/s) is clipped to ±1 as an action; with action_lag = 1,
    frame t is paired with the command computed from frame t − 1 and frame 0 is no sample."""
    dataset = Dataset.create(tmp_path / "d", {"collect": {}}, seed=0)
    run = make_run("train", 0, 22)
    fast = Run(**{**{f: getattr(run, f) for f in ("meta", "images", "scans", "bins", "poses", "times")},
                  "actions": (run.actions * 2.5).astype(np.float32)})
    dataset.add_run(fast, jpeg_quality=90)
    depth = view_arrays(dataset, "train", None, bins_target, CONFIG)
    np.testing.assert_array_equal(depth["action"], np.clip(fast.actions[:16], -1, 1))
    assert np.abs(fast.actions[:-1]).max() > 1
    lagged = view_arrays(dataset, "train", None, bins_target, replace(CONFIG, action_lag=1))
    np.testing.assert_array_equal(lagged["frame_id"], np.arange(1, 16))
    np.testing.assert_array_equal(lagged["action"], np.clip(fast.actions[:15], -1, 1))
    np.testing.assert_array_equal(lagged["target"], fast.bins[2:17])
    coll = view_arrays(dataset, "train", None, collision_target, replace(CONFIG, action_lag=1))
    assert coll["frame_id"][0] == 1 and coll["target"].tolist() == [0] * 15 + [1] * 5


def test_views_sample_deterministically(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "d", [20, 30, 22, 21])
    view = FrameView(dataset, "train", view_arrays(dataset, "train", None, bins_target, CONFIG))

    def batches(seed: int, workers: int = 0) -> list[torch.Tensor]:
        loader = DataLoader(view, batch_size=8, sampler=view.sampler(32, seed), num_workers=workers)
        return [
            torch.cat([image.flatten(), action, target.flatten()]).nan_to_num(-1)
            for image, action, target in loader
        ]

    first, again, other = batches(3), batches(3, workers=2), batches(4)  # files already open when forking
    assert all(torch.equal(a, b) for a, b in zip(first, again, strict=True))
    assert not all(torch.equal(a, b) for a, b in zip(first, other, strict=True))
    image, action, target = next(iter(DataLoader(view, batch_size=8, sampler=view.sampler(8, 0))))
    assert image.shape == (8, *SMALL, 3) and image.dtype == torch.uint8
    assert action.dtype == torch.float32 and target.shape == (8, 26)
    # a random run, then a random frame: runs are drawn equally often whatever their length
    offsets = view.arrays["run_offsets"]
    draws = run_then_frame(offsets, 40_000, np.random.default_rng(0))
    per_run = np.bincount(np.searchsorted(offsets, draws, side="right") - 1, minlength=4)
    assert np.allclose(per_run / 40_000, 0.25, atol=0.01)


def test_stats_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    make_dataset(tmp_path / "d", [20, 10, 30, 25, 22])  # run 1 too short; run 2 ends at the time limit
    stats = dataset_stats(Dataset.open(tmp_path / "d"), CONFIG)
    rows = {row["subset"]: row for row in stats["table"]}
    assert list(rows) == ["2", "4", "all", "val"]
    assert rows["2"] == {
        "subset": "2",
        "runs": 2,
        "samples": 19 + 29,
        "samples_without_collision": 14 + 24,
        "mean_run_length": 25.0,
        "collision_fraction": 0.5,
    }
    assert rows["4"]["samples"] == 19 + 29 + 24 + 21 and rows["val"]["runs"] == 1
    assert stats["collected"] == {"train": 5, "val": 1} and stats["usable"] == {"train": 4, "val": 1}
    assert main(["dataset", "stats", str(tmp_path / "d"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["table"][0] == {**rows["all"]}  # no paper subset fits
    assert main(["dataset", "stats", str(tmp_path / "d")]) == 0
    assert "w/o collision" in capsys.readouterr().out
