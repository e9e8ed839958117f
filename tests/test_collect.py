"""Collection in real MuJoCo: determinism across workers, resume after kill -9, config guard."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.data.collect import CollectConfig, collect
from depthq.data.manifest import Dataset
from depthq.errors import ConfigError

ARGS = ["--runs", "4", "--val-runs", "1", "--max-steps", "40", "--seed", "3"]
CONFIG = CollectConfig(runs=4, val_runs=1, max_steps=40)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Dataset:
    """An uninterrupted single-process collection."""
    return collect(tmp_path_factory.mktemp("ref") / "ds", CONFIG, seed=3, workers=1, progress=False)


def arrays(dataset: Dataset) -> dict[str, dict[str, np.ndarray]]:
    out = {}
    for entry in dataset.entries():
        run = dataset.read_run(entry)
        out[run.meta.name] = {k: getattr(run, k) for k in ("scans", "bins", "actions", "poses", "times")}
        out[run.meta.name]["images"] = run.images
    return out


def test_runs_are_real_exploration_runs(reference):
    entries = reference.entries()
    assert [(e.split, e.index) for e in entries] == [("train", i) for i in range(4)] + [("val", 0)]
    run = reference.read_run(entries[0])
    assert run.images.shape[1:] == (308, 410, 3)
    assert np.isnan(run.actions[-1]) and np.all(np.abs(run.actions[:-1]) <= 1)
    assert run.actions[0] == 0.0  # OU restarts at 0 every run
    assert run.meta.end_reason in ("bump", "contact", "step_limit")
    assert np.all(np.diff(run.times) > 0)


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
    assert 1 <= recorded < 5, "the kill should land mid-collection"
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
        collect(reference.root, CollectConfig(runs=5, val_runs=1, max_steps=40), seed=3, progress=False)


def test_cli_rejects_bad_values(tmp_path, capsys):
    assert main(["collect", "--runs", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--runs" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_resume_is_a_no_op_when_complete(reference):
    before = {p: p.stat().st_mtime_ns for p in Path(reference.root).rglob("*.h5")}
    collect(reference.root, CONFIG, seed=3, workers=1, progress=False)
    assert {p: p.stat().st_mtime_ns for p in Path(reference.root).rglob("*.h5")} == before
