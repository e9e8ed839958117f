"""Collection in real MuJoCo: determinism across workers, resume after kill -9, config guard."""

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.configio import to_dict
from depthq.data.manifest import Dataset
from depthq.data.recorder import CollectConfig, collect
from depthq.errors import ConfigError
from depthq.sim.world import TURTLEBOT3_MAX_YAW_RATE

ARGS = ["--runs", "4", "--val-runs", "1", "--max-steps", "40", "--seed", "3"]
CONFIG = CollectConfig(runs=4, val_runs=1, max_steps=40, seed=3)  # the reference collection's


@pytest.fixture
def reference(reference_collection: Dataset) -> Dataset:
    """An uninterrupted single-process collection (conftest's, shared with the Ray test). Not the small
    dataset: it is the collection under test, with the config and seed of `ARGS` that the CLI
    collections repeat."""
    assert reference_collection.config == CONFIG.recorded() and reference_collection.seed == 3
    assert "seed" not in reference_collection.config and "seed" in to_dict(CONFIG)  # the manifest as before
    return reference_collection


def arrays(dataset: Dataset) -> dict[str, dict[str, np.ndarray]]:
    out = {}
    for entry in dataset.entries():
        run = dataset.read_run(entry)
        out[run.meta.name] = {k: getattr(run, k) for k in ("scans", "bins", "actions", "poses", "times")}
        out[run.meta.name]["images"] = run.images
    return out


def test_runs_are_real_exploration_runs(reference):
    entries = reference.entries()
    for split, wanted in (("train", 4), ("val", 1)):  # short runs (< 20 frames) are kept but do not count
        indices = [e.index for e in entries if e.split == split]
        assert indices == list(range(len(indices)))
        assert sum(e.n_frames >= 20 for e in entries if e.split == split) == wanted
    run = reference.read_run(next(e for e in entries if e.n_frames >= 20))
    assert run.images.shape[1:] == (308, 410, 3)
    # The command is stored unclipped, up to the robot's limit; samples clip it later.
    assert np.isnan(run.actions[-1]) and np.all(np.abs(run.actions[:-1]) <= TURTLEBOT3_MAX_YAW_RATE)
    assert run.meta.end_reason in ("bump", "contact", "time_limit", "step_limit")
    assert np.all(np.diff(run.times) > 0)
    # The first 9 frames were driven but not saved: the stored run starts 9 decision periods in.
    period = CONFIG.env.world.period
    assert run.times[0] == pytest.approx(9 * period) and np.allclose(np.diff(run.times), period)


def test_runs_replay_the_original_recorder_without_a_camera():
    """Frames 0..8 are dropped from the very same drive: a run without skipping holds them first."""
    from depthq.data.recorder import collect_run
    from depthq.sim.env import CanyonEnv

    env = CanyonEnv(CONFIG.env, camera=False)
    try:
        kept = collect_run(env, CONFIG, 3, "train", 1)
        full = collect_run(env, replace(CONFIG, skip_frames=0), 3, "train", 1)
    finally:
        env.close()
    assert full.n_frames == kept.n_frames + 9
    np.testing.assert_array_equal(full.poses[9:], kept.poses)
    np.testing.assert_array_equal(full.actions[9:], kept.actions)
    assert full.meta.end_reason == kept.meta.end_reason


@pytest.mark.slow
def test_interrupted_collection_resumes_to_identical_arrays(reference, tmp_path):
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "depthq.cli", "collect", *ARGS, "--workers", "2", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    manifest = out / "manifest.json"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # kill -9 the whole group once the first run is recorded
        if manifest.is_file() and json.loads(manifest.read_text())["runs"]:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    recorded = len(json.loads(manifest.read_text())["runs"])
    assert 1 <= recorded < len(reference.entries()), "the kill should land mid-collection"
    assert main(["collect", *ARGS, "--workers", "2", "--out", str(out)]) == 0
    resumed = Dataset.open(out)
    assert [e.sha256 for e in resumed.entries()] == [e.sha256 for e in reference.entries()]
    got, want = arrays(resumed), arrays(reference)
    assert got.keys() == want.keys()
    for name in want:
        for key in want[name]:
            np.testing.assert_array_equal(got[name][key], want[name][key], err_msg=f"{name}/{key}")
    assert not list((out / "runs").glob(".*.tmp"))


def test_collecting_into_a_folder_with_another_config_refuses(reference):
    with pytest.raises(ConfigError, match="runs"):
        collect(reference.root, CollectConfig(runs=5, val_runs=1, max_steps=40, seed=3), progress=False)


def test_a_run_does_not_depend_on_how_many_are_collected(reference, tmp_path):
    """Why `depthq sweep --runs 500` trains the models a 900-run dataset would: run i is the same."""
    fewer = collect(tmp_path / "ds", replace(CONFIG, runs=2), workers=1, progress=False)
    assert len(fewer.entries("train")) >= 2 and len(fewer.entries()) < len(reference.entries())
    assert [e.sha256 for e in fewer.entries()] == [reference.entry(e.split, e.index).sha256
                                                  for e in fewer.entries()]


def test_cli_rejects_bad_values(tmp_path, capsys):
    assert main(["collect", "--runs", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--runs" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_resume_is_a_no_op_when_complete(reference):
    before = {p: p.stat().st_mtime_ns for p in Path(reference.root).rglob("*.h5")}
    collect(reference.root, CONFIG, workers=1, progress=False)
    assert {p: p.stat().st_mtime_ns for p in Path(reference.root).rglob("*.h5")} == before


def test_probe_statistics_on_train_canyons_and_no_eval_canyons(tmp_path, capsys):
    """Table II statistics of OU runs without a camera (the oracles: tests/test_oracle.py)."""
    from depthq.evaluate.probe import PAPER_FRAMES_PER_RUN, format_stats, ou_statistics

    stats = ou_statistics(4.0, runs=6)
    assert stats["runs"] == 6 and 0 < stats["kept_share"] <= 1 and stats["frames_per_kept_run"] >= 20
    assert stats["samples"][900] == round(900 * (stats["frames_per_kept_run"] - 1))
    assert f"{PAPER_FRAMES_PER_RUN:.1f}" in format_stats([stats])
    assert main(["probe", "--canyons", "eval:0-3", "--out", str(tmp_path / "p")]) == 2
    assert "test set" in capsys.readouterr().err and not (tmp_path / "p").exists()


def test_a_collection_in_a_folder_look_does_not_resume_with_other_images(tmp_path, capsys):
    """The manifest records the look folder's images by SHA-256: a collection resumed after they were
    added, removed or changed would mix two looks, and is refused naming them, the dataset untouched."""
    from PIL import Image

    from depthq.checksum import file_sha256

    look = tmp_path / "look"
    look.mkdir()
    rng = np.random.default_rng(2)
    for name in ("a.png", "b.png", "c.png"):
        Image.fromarray(rng.integers(0, 256, (32, 32, 3), dtype=np.uint8)).save(look / name)
    out = tmp_path / "data"
    argv = ["collect", "--look", str(look), "--runs", "2", "--val-runs", "0", "--max-steps", "30",
            "--workers", "1", "--out", str(out)]
    assert main(argv) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["look_images"] == {p.name: file_sha256(p) for p in sorted(look.iterdir())}
    last = manifest["runs"].pop()  # as a collection killed before its last run left it
    (out / last["file"]).unlink()
    (out / "manifest.json").write_text(json.dumps(manifest))
    before = {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    capsys.readouterr()
    Image.fromarray(np.zeros((32, 32, 3), np.uint8)).save(look / "a.png")  # changed
    (look / "b.png").unlink()  # removed
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(look / "d.png")  # added
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "added d.png; removed b.png; changed a.png" in err, err
    assert {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()} == before
    # a manifest written before it recorded the images resumes, and records them as they are now
    del manifest["look_images"]
    (out / "manifest.json").write_text(json.dumps(manifest))
    assert main(argv) == 0
    resumed = json.loads((out / "manifest.json").read_text())
    assert resumed["look_images"] == {p.name: file_sha256(p) for p in sorted(look.iterdir())}
    assert len(resumed["runs"]) == len(manifest["runs"]) + 1
