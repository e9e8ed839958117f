"""The camera-labels experiment (`research.camera_labels`, issue #32 item 3) at toy size, on
the suite's smoke sweep (read, never changed): a floor labeller, the labelled hard-linked copy and its
stats, a camera-label Depth-Q-Net, the sweep's own Depth-Q-Net and Coll-Q-Net, all driven in one
`val` canyon; the table; a rerun that does nothing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from depthq.checkpoint import read_config
from depthq.data.manifest import Dataset
from research import camera_labels, label_bands

TOY = [
    "--method", "floor", "--runs", "6", "--seeds", "0", "--canyons", "val:1000", "--time-limit", "5",
    "--device", "cpu", "--no-progress",
    *("--labeller-set", "steps=5", "--labeller-set", "pool_runs=2", "--labeller-set", "pool_frames=3",
      "--labeller-set", "batch_size=4", "--labeller-set", "width=8"),
    *("--set", "epochs=1", "--set", "train_batches=2", "--set", "val_batches=1", "--set", "batch_size=8"),
]


def _stamps(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()}


def _summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


@pytest.mark.slow  # the smoke sweep (~1 min, shared), a labeller, a training and 3 evaluations: ~2 min
def test_the_experiment_labels_a_copy_trains_drives_tabulates_and_resumes(
    smoke: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "paper"
    sweep_data = Dataset.open(smoke / "data")
    before = sweep_data.fingerprint()
    assert camera_labels.main(["run", str(smoke), str(out), *TOY]) == 0
    printed = capsys.readouterr().out

    setup = json.loads((out / "setup.json").read_text())
    assert setup == {"sweep": str(smoke.resolve()), "family": "paper", "canyons": "val:1000",
                     "time_limit_s": 5.0, "weights": None}
    labeller = json.loads((out / "floor" / "labeller" / "config.json").read_text())
    assert labeller["name"] == "floor" and labeller["config"]["steps"] == 5
    assert labeller["config"]["data"] == str((smoke / "data").resolve())  # learnt on the data it labels
    labelled = Dataset.open(out / "floor" / "data")
    for entry in labelled.entries():
        with labelled.reader(entry) as reader:
            assert reader.camera_labels().fingerprint == labeller["fingerprint"]
    assert Dataset.open(smoke / "data").fingerprint() == before  # the sweep's runs are untouched
    with sweep_data.reader(sweep_data.entries()[0]) as reader:
        assert reader.camera_labels() is None
    stats = json.loads((out / "floor" / "stats.json").read_text())
    error = stats["camera_labels"]["splits"]["train"]
    assert error["runs"] == len(labelled.entries("train")) and error["nearest"]["median"] is not None
    assert "camera labels (floor" in (out / "floor" / "stats.txt").read_text()

    train = read_config(out / "floor" / "models" / "depth_n6_s0")["train"]
    sweep_train = read_config(smoke / "models" / "depth_n6_s0")["train"]
    assert train["labels"] == "camera" and train["data"] == str((out / "floor" / "data").resolve())
    assert (train["epochs"], train["train_batches"], train["runs"], train["seed"]) == (1, 2, 6, 0)
    assert train["depth"] == sweep_train["depth"] and train["lr"] == sweep_train["lr"]
    evaluations = {name: out / where / "eval" / model for name, where, model in (
        ("camera", "floor", "depth_n6_s0"), ("lidar", "lidar", "depth_n6_s0"), ("coll", "lidar", "coll_n6_s0")
    )}
    summaries = {}
    for name, folder in evaluations.items():
        result = _summary(folder)
        assert result["config"]["canyons"] == ["val:1000"] and result["config"]["weights"] is None
        assert result["config"]["time_limit_s"] == 5.0 and not (folder / "video.mp4").exists()
        summaries[name] = result["summary"]

    assert camera_labels.main(["table", str(out), "--runs", "6", "--seeds", "0", "--no-progress"]) == 0
    text = capsys.readouterr().out.strip()
    assert printed.strip().endswith(text)  # `run` ends with the same table
    lines = text.splitlines()
    assert len(lines) == 5 and lines[0].startswith("| family (sweep) | canyons | Q-net, labels |")
    cells = [line.split(" | ") for line in lines[2:]]
    assert [c[2] for c in cells] == ["Depth-Q-Net, camera labels: floor (camera + odometry), 6 runs",
                                     "Depth-Q-Net, LiDAR labels, 6 runs", "Coll-Q-Net, 6 runs"]
    assert all(c[0] == "| paper (`out`)" and c[1] == "val:1000" and c[7] == "0" for c in cells)
    assert cells[0][3] == f"{error['nearest']['median']:.3f} [{error['nearest']['mean']:.3f}]"
    assert cells[1][3] == cells[2][3] == "–"
    for row, name in zip(cells, ("camera", "lidar", "coll"), strict=True):
        s = summaries[name]
        assert row[8] == row[9] == f"{s['distance_to_collision_mean']:.2f}"
        assert (row[10], row[11]) == (str(s["reached_end"]), str(s["collisions"]))
    camera, lidar = (summaries[k]["distance_to_collision_mean"] for k in ("camera", "lidar"))
    share = camera / lidar
    assert cells[0][12].startswith(f"{share:.0%} ") and cells[1][12] == cells[2][12] == "– |"

    stamps = _stamps(out)
    assert camera_labels.main(["run", str(smoke), str(out), *TOY]) == 0  # resumed: nothing done again
    assert _stamps(out) == stamps
    capsys.readouterr()
    other = [*TOY[: TOY.index("--canyons") + 1], "val:1001", *TOY[TOY.index("--canyons") + 2 :]]
    assert camera_labels.main(["run", str(smoke), str(out), *other]) == 2  # evaluations not comparable
    assert "another setup (canyons 'val:1000' there, 'val:1001' here)" in capsys.readouterr().err
    assert camera_labels.main(["run", str(smoke), str(tmp_path / "p"), "--method", "perception"]) == 2
    assert "--labeller-data" in capsys.readouterr().err and not (tmp_path / "p").exists()
    assert _stamps(out) == stamps

    # The band diagnostic on the same folder: the LiDAR's bins under 1 m in the camera labels' place.
    argv = ["run", str(out), "--band", "near", "--split", "1", "--runs", "6", "--device", "cpu",
            "--no-progress"]
    assert label_bands.main([*argv, *TOY[TOY.index("--set") :]]) == 0
    assert "| LiDAR under 1 m, camera beyond | 0 |" in capsys.readouterr().out
    mix = Dataset.open(out / "bands" / "near_1" / "data")
    for entry in mix.entries():
        run = mix.read_run(entry, images=False)
        with labelled.reader(labelled.entry(entry.split, entry.index)) as reader:
            camera = reader.camera_labels().bins
        expected = label_bands.mixed(run.bins, camera, "near", 1.0)
        assert np.array_equal(run.camera.bins, expected, equal_nan=True)
        assert run.camera.labeller == label_bands.NAME
    assert _summary(out / "bands" / "near_1" / "eval" / "depth_n6_s0")["config"]["canyons"] == ["val:1000"]
