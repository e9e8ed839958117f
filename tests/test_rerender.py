"""Re-rendered looks (`depthq dataset rerender`) in real MuJoCo: a run rendered in its own look is its
recorded run; other looks keep every non-image byte; resumed after kill -9; verified; trained on."""

import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from depthq.cli import main
from depthq.configio import from_dict
from depthq.control.ou import OUConfig
from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.recorder import CollectConfig, collect, exploration_env, run_seeds
from depthq.data.rerender import STRIDE, dataset_env, render_frames, verify_rendered
from depthq.data.runfile import encode_jpeg, write_run
from depthq.data.samples import bins_target
from depthq.data.stats import dataset_stats, format_stats
from depthq.data.subsets import first_runs, select_runs, usable_runs
from depthq.data.views import view_arrays
from depthq.sim.canyon import CanyonId, generate_canyon
from depthq.sim.world import CanyonWorld

LOOKS = ("colours", "textured")
ARRAYS = ("scans", "bins", "actions", "poses", "times")


def _collect(root: Path, look: str) -> Path:
    """2 training runs and 1 validation run of <= 30 steps (9 of them skipped), seed 0, in `look`."""
    env = exploration_env()
    env = replace(env, world=replace(env.world, look=look))
    collect(root, CollectConfig(runs=2, val_runs=1, max_steps=30, env=env), workers=1, progress=False)
    return root


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    return _collect(tmp_path_factory.mktemp("tiny") / "data", "flat")


@pytest.fixture(scope="module")
def rendered(tiny: Path, tmp_path_factory) -> Path:
    """`tiny` with its runs rendered again in colours and textured, in one uninterrupted call."""
    root = tmp_path_factory.mktemp("rendered") / "data"
    shutil.copytree(tiny, root)
    assert main(["dataset", "rerender", str(root), "--looks", ",".join(LOOKS), "--workers", "1"]) == 0
    return root


def _replayed(root: Path) -> list[tuple[list[bytes], np.ndarray, np.ndarray]]:
    """Per run: its stored JPEGs, their decoded frames, and its frames rendered again in its own look
    from its own seeds (the canyon's appearance seed, the collector's env seed)."""
    dataset = Dataset.open(root)
    world_config = dataset_env(dataset).world
    world, ou = CanyonWorld(world_config), from_dict(OUConfig, dataset.config["ou"])
    out = []
    try:
        for entry in dataset.entries():
            with dataset.reader(entry) as reader:
                run, jpegs = reader.run(), [reader.jpeg(t) for t in range(len(reader))]
            canyon = CanyonId(entry.canyon_split, entry.canyon_index, world_config.family)
            frames = np.random.default_rng(run_seeds(dataset.seed, entry.split, entry.index)[0])
            again = render_frames(world, run, generate_canyon(canyon, world_config.canyon),
                                  np.random.default_rng(canyon.appearance_seed), frames, ou)
            out.append((jpegs, run.images, again))
    finally:
        world.close()
    return out


@pytest.mark.parametrize("data", ["tiny", "small_hard_dataset"])
def test_a_run_rendered_in_its_own_look_is_its_recorded_run(data: str, request: pytest.FixtureRequest
                                                             ) -> None:
    """Flat (the paper family's) and colours (the hard family's, its pillars): the JPEG the collector
    stored, byte for byte, for all but frames whose float32 pose moves an edge by a pixel (none to 1 in
    100 here), and even those within 0.05 grey levels."""
    identical = total = 0
    for jpegs, _, again in _replayed(request.getfixturevalue(data)):
        for stored, frame in zip(jpegs, again, strict=True):
            encoded = encode_jpeg(frame, 90)
            identical += encoded == stored
            total += 1
            assert _mean_abs(encoded, stored) < 0.05
    assert identical >= 0.95 * total, f"{identical} of {total} frames byte-identical"


@pytest.mark.slow  # a textured collection (~12 s)
def test_a_textured_run_rendered_again_is_its_recorded_run_within_float32_poses(tmp_path: Path) -> None:
    """Textured: the robot camera's exposure, white balance, blur and noise follow the collector's, so
    the frames differ only by the float32 poses' sub-pixel shifts, spread by auto-exposure and JPEG:
    < 0.5 grey levels on average (0.06-0.21 measured), where another camera draw differs by > 5."""
    root = _collect(tmp_path / "data", "textured")
    for jpegs, images, again in _replayed(root):
        for stored, frame in zip(jpegs, again, strict=True):
            assert _mean_abs(encode_jpeg(frame, 90), stored) < 0.5
        assert np.abs(again.astype(int) - images).mean() > 0.5  # the frames are the noisy camera's
    dataset = Dataset.open(root)
    entry = dataset.entries()[0]
    world_config = dataset_env(dataset).world
    world = CanyonWorld(world_config)
    run = dataset.read_run(entry)
    canyon = CanyonId(entry.canyon_split, entry.canyon_index, world_config.family)
    other = render_frames(world, run, generate_canyon(canyon, world_config.canyon),  # another camera draw
                          np.random.default_rng(canyon.appearance_seed), np.random.default_rng(1),
                          from_dict(OUConfig, dataset.config["ou"]))
    world.close()
    assert np.abs(other.astype(int) - run.images).mean() > 5


def _mean_abs(a: bytes, b: bytes) -> float:
    decode = lambda data: np.asarray(Image.open(io.BytesIO(data)), dtype=np.int16)  # noqa: E731
    return float(np.abs(decode(a) - decode(b)).mean())


def test_other_looks_keep_every_byte_but_the_frames(tiny: Path, rendered: Path) -> None:
    source, dataset = Dataset.open(tiny), Dataset.open(rendered)
    collected = source.entries()
    assert [e for e in dataset.entries() if e.rendered is None] == collected
    again = [e for e in dataset.entries() if e.rendered is not None]
    assert len(again) == len(LOOKS) * len(collected)
    for v, look in enumerate(LOOKS, start=1):
        for entry in collected:
            copy = dataset.entry(entry.split, v * STRIDE + entry.index)  # a val run's re-render is a val run
            assert (copy.rendered.source, copy.rendered.look, copy.rendered.seed) == (entry.index, look, 1)
            assert copy.file == f"runs/{entry.split}_{v * STRIDE + entry.index:06d}.h5"
            mine, theirs = dataset.read_run(copy), source.read_run(entry)
            assert replace(mine.meta, index=entry.index) == theirs.meta
            for name in ARRAYS:
                assert getattr(mine, name).tobytes() == getattr(theirs, name).tobytes(), name
            assert mine.camera is None
            assert np.abs(mine.images.astype(int) - theirs.images).mean() > 5, "a new look's frames"
    assert verify_rendered(dataset) == []
    assert main(["dataset", "verify", str(rendered)]) == 0
    colours = dataset.read_run(dataset.entry("train", STRIDE)).images
    textured = dataset.read_run(dataset.entry("train", 2 * STRIDE)).images
    assert np.abs(colours.astype(int) - textured).mean() > 5


def test_a_call_again_adds_nothing_and_a_new_seed_adds_a_draw(rendered: Path, tmp_path: Path) -> None:
    root = tmp_path / "data"
    shutil.copytree(rendered, root)
    manifest = (root / "manifest.json").read_bytes()
    assert main(["dataset", "rerender", str(root), "--looks", "textured", "--workers", "1"]) == 0
    assert (root / "manifest.json").read_bytes() == manifest
    dataset = Dataset.open(root)
    val = [e for e in dataset.entries("val") if e.rendered is None]
    _keep_only(root, val[0])  # one collected run and its looks: the new draw is rendered for it alone
    argv = ["dataset", "rerender", str(root), "--looks", "textured", "--seed", "2", "--workers", "1"]
    assert main(argv) == 0
    dataset = Dataset.open(root)
    new = dataset.entry("val", 3 * STRIDE + val[0].index)
    assert (new.rendered.look, new.rendered.seed) == ("textured", 2)
    old = dataset.entry("val", 2 * STRIDE + val[0].index)
    assert np.abs(dataset.read_run(new).images.astype(int) - dataset.read_run(old).images).mean() > 5


def _keep_only(root: Path, keep) -> None:
    """The dataset in `root` cut to run `keep` and its re-renders (to render a new draw of one run)."""
    data = json.loads((root / "manifest.json").read_text())
    rows = [r for r in data["runs"] if (r["split"], r["index"] % STRIDE) == (keep.split, keep.index)]
    for row in data["runs"]:
        if row not in rows:
            (root / row["file"]).unlink()
    (root / "manifest.json").write_text(json.dumps({**data, "runs": rows}))


@pytest.mark.slow  # two re-renderings, one killed (~40 s)
def test_a_rerendering_killed_resumes_to_the_same_bytes(tiny: Path, rendered: Path, tmp_path: Path) -> None:
    root = tmp_path / "data"
    shutil.copytree(tiny, root)
    cmd = [sys.executable, "-m", "depthq.cli", "dataset", "rerender", str(root), "--looks", ",".join(LOOKS),
           "--workers", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    manifest, before = root / "manifest.json", len(Dataset.open(tiny).entries())
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # kill -9 the whole group once the first re-render is recorded
        if len(json.loads(manifest.read_text())["runs"]) > before:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    recorded = len(json.loads(manifest.read_text())["runs"])
    assert before < recorded < len(Dataset.open(rendered).entries()), "the kill should land mid-way"
    assert main(["dataset", "rerender", str(root), "--looks", ",".join(LOOKS), "--workers", "2"]) == 0
    resumed, want = json.loads(manifest.read_text()), json.loads((rendered / "manifest.json").read_text())
    assert resumed["runs"] == want["runs"]  # every file's hash: 2 workers, killed, as one uninterrupted call
    assert not list((root / "runs").glob(".*.tmp"))
    assert _files(root) == _files(rendered)


def test_verify_names_a_rerender_whose_data_is_not_its_source(rendered: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "data"
    shutil.copytree(rendered, root)
    dataset = Dataset.open(root)
    entry = dataset.entry("train", STRIDE)
    run = dataset.read_run(entry)
    poses = run.poses.copy()
    poses[1, 0] += 0.01
    info = write_run(dataset.path(entry), replace(run, poses=poses))  # a faulty re-render, its row updated
    data = json.loads((root / "manifest.json").read_text())
    for row in data["runs"]:
        if row["file"] == entry.file:
            row.update(sha256=info.sha256, bytes=info.bytes)
    (root / "manifest.json").write_text(json.dumps(data))
    problems = verify_rendered(Dataset.open(root))
    assert len(problems) == 1 and "train_1000000.h5: differs from its source" in problems[0]
    assert "in poses;" in problems[0]
    assert main(["dataset", "verify", str(root)]) == 1
    assert "differs from its source" in capsys.readouterr().err


def test_training_views_and_labeller_pools_take_n_collected_runs_and_their_looks(rendered: Path) -> None:
    dataset = Dataset.open(rendered)
    first = usable_runs(dataset, "train", 20)[0]
    assert all(e.rendered is None for e in usable_runs(dataset, "train", 20))  # Table II's: collected runs
    chosen = select_runs(dataset, "train", 1, 20)
    assert [e.index for e in chosen] == [first.index, STRIDE + first.index, 2 * STRIDE + first.index]
    pool = first_runs(dataset, "train", 1, every_look=True)  # a labeller's: the first collected run
    assert [e.index for e in pool] == [0, STRIDE, 2 * STRIDE]  # in every look
    assert len(first_runs(dataset, "train", 10, every_look=True)) == len(dataset.entries("train"))
    collected = [e for e in dataset.entries("train") if e.rendered is None]
    assert first_runs(dataset, "train", 10, every_look=False) == collected  # as collected
    assert first_runs(dataset, "train", 1, every_look=False) == collected[:1]
    arrays = view_arrays(dataset, "val", None, bins_target)
    val = [e.index for e in dataset.entries("val") if e.rendered is None]
    assert sorted(set(arrays["run_id"].tolist())) == sorted(v * STRIDE + i for v in range(3) for i in val)
    counts = np.diff(arrays["run_offsets"])
    assert (counts == counts[0]).all()  # each look of a run: the same samples
    stats = dataset_stats(dataset, DataConfig())
    collected = {split: sum(e.rendered is None for e in dataset.entries(split)) for split in ("train", "val")}
    assert stats["collected"] == collected and stats["rendered_looks"] == ["colours:1", "textured:1"]
    assert stats["rendered"] == {split: len(LOOKS) * n for split, n in collected.items()}
    assert "rendered again in 2 look(s) (colours:1, textured:1)" in format_stats(stats)


@pytest.mark.slow  # features of every frame and a toy training (~30 s)
def test_a_net_trains_on_every_look_and_the_cache_holds_each(rendered: Path, tmp_path: Path) -> None:
    from depthq.train.config import TrainConfig
    from depthq.train.features import features_ready
    from depthq.train.trainer import train

    root = tmp_path / "data"
    shutil.copytree(rendered, root)
    fast = {"epochs": 1, "train_batches": 2, "val_batches": 1, "batch_size": 16}
    folder = train(TrainConfig(model="depth", data=str(root), **fast), tmp_path / "net", progress=False)
    assert (folder / "config.json").is_file()
    dataset = Dataset.open(root)
    index = next((root / "features").rglob("index.json"))
    runs = json.loads(index.read_text())["runs"]
    assert set(runs) == {e.name for e in dataset.entries()}  # K looks: K + 1 times the collected rows
    assert sum(n for _, n in runs.values()) == sum(e.n_frames for e in dataset.entries())
    assert features_ready(dataset, json.loads(index.read_text())["trunk"],
                          json.loads(index.read_text())["input_size"])
    from research import coll_learning  # measured per look of its validation runs

    coll = train(TrainConfig(model="coll", data=str(root), **fast), tmp_path / "coll", progress=False)
    assert [row["look"] for row in coll_learning.measure(coll)] == ["flat", *LOOKS]


def test_bad_input_is_refused_and_writes_nothing(tiny: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "data"
    shutil.copytree(tiny, root)
    manifest = (root / "manifest.json").read_bytes()
    for looks, message in (("nosuchlook", "unknown look 'nosuchlook'"), ("broad,broad", "names broad twice"),
                           (",", "names no look")):
        assert main(["dataset", "rerender", str(root), "--looks", looks]) == 2
        assert message in capsys.readouterr().err
    assert main(["dataset", "rerender", str(root), "--looks", "broad", "--seed", "-1"]) == 2
    assert "--seed must be an integer >= 0" in capsys.readouterr().err
    assert main(["dataset", "rerender", str(tmp_path / "none"), "--looks", "broad"]) == 2
    assert (root / "manifest.json").read_bytes() == manifest
    assert _files(root) == _files(tiny)


def _files(root: Path) -> list[str]:
    return sorted(path.name for path in (root / "runs").iterdir())


@pytest.mark.slow  # a toy labeller's training and a labelling (~20 s)
def test_every_look_of_a_run_is_labelled_from_its_own_frames(rendered: Path, small_hard_dataset: Path,
                                                             tmp_path: Path) -> None:
    from depthq.labellers.labeller import LabellerConfig, train_labeller

    root = tmp_path / "data"
    shutil.copytree(rendered, root, ignore=shutil.ignore_patterns("features"))
    toy = {"method": "perception", "hidden": 64, "steps": 20, "batch_size": 16, "lr": 1.0, "input_size": 64}
    labeller = train_labeller(LabellerConfig(data=str(small_hard_dataset), **toy), tmp_path / "labeller",
                              progress=False, device="cpu")  # another family's LiDAR, as `label` asks
    assert main(["label", str(root), "--from", "camera", "--labeller", str(labeller), "--no-progress"]) == 0
    dataset = Dataset.open(root)
    source = usable_runs(dataset, "train", 20)[0]
    looks = [dataset.read_run(dataset.entry("train", v * STRIDE + source.index), images=False)
             for v in range(len(LOOKS) + 1)]
    assert all(run.camera is not None for run in looks)
    assert looks[0].camera.bins.tobytes() != looks[2].camera.bins.tobytes()  # each look's own frames
    assert verify_rendered(dataset) == []  # labels are not among what a re-render copies
    arrays = view_arrays(dataset, "train", 1, bins_target, labels="camera")
    assert set(arrays["run_id"].tolist()) == {v * STRIDE + source.index for v in range(len(LOOKS) + 1)}


def test_bench_rerender_prints_each_looks_frames_per_second(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "rerender", "--runs", "1", "--looks", "colours", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    colours = result["looks"]["colours"]
    assert colours["frames"] == result["collect"]["frames"] > 0 and colours["frames_per_s"] > 0
    assert colours["kb_per_frame"] > 0
    assert main(["bench", "rerender", "--looks", "colours,neon"]) == 2
