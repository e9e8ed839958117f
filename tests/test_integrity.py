"""Nothing silently wrong (#46): one writer per output folder, every file a result depends on checked
where it is read, every bad value refused before any work, strict JSON, byte-identical checkpoints.
Each test provokes its defect for real: two processes, a flipped byte, a `kill -9`."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from depthq.blocks.trunk import DEFAULT_TRUNK
from depthq.checkpoint import load_qnet, read_sidecar, weights_bytes
from depthq.checksum import KEY
from depthq.cli import main
from depthq.configio import read_json, write_json
from depthq.data.manifest import MANIFEST, Dataset
from depthq.errors import ConfigError, DataError
from depthq.lock import exclusive, lock_path
from depthq.train.features import ARRAY, cache_dir, load_features

FAST = {"train_batches": 8, "val_batches": 1, "batch_size": 16}


def _python(code: str) -> subprocess.Popen:
    """`code` in another Python process, this checkout's package first, its stdout piped."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")}
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=env)


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


# --- the lock ---------------------------------------------------------------------------------------


def test_a_second_writer_is_refused_with_the_holders_pid_and_a_killed_holders_lock_never_blocks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    holder = _python(f"from depthq.lock import exclusive\nwith exclusive({str(out)!r}):\n"
                     "    print('held', flush=True)\n    import time; time.sleep(60)\n")
    try:
        assert holder.stdout.readline().strip() == "held"
        assert main(["drive", "--out", str(out), "--canyon", "eval:0"]) == 2
        assert f"PID {holder.pid}" in _one_line(capsys)
        assert not out.exists()  # refused before any work
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert lock_path(out).is_file()  # the killed holder's lock file is left behind ...
    with exclusive(out):  # ... and does not block: the kernel released its lock
        assert lock_path(out).read_text().strip() == str(os.getpid())
    assert not lock_path(out).exists() and not out.exists()


@pytest.mark.parametrize("verb", [
    ["collect"], ["labeller", "--data", "d", "--method", "floor"], ["sweep"], ["evaluate", "heuristic"],
    ["drive"], ["export", "ckpt"], ["train", "--model", "depth", "--data", "d"],
])
def test_out_naming_an_existing_file_is_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], verb: list[str]
) -> None:
    out = tmp_path / "results.txt"
    out.write_text("mine")
    assert main([*verb, "--out", str(out)]) == 2
    assert "exists and is not a folder" in _one_line(capsys)
    assert out.read_text() == "mine" and sorted(p.name for p in tmp_path.iterdir()) == ["results.txt"]


# --- bad values: one line, exit 2, nothing written --------------------------------------------------


@pytest.mark.parametrize("args", [
    ["collect", "--seed", "-1"], ["evaluate", "heuristic", "--seed", "-1"], ["drive", "--seed", "-1"],
    ["collect", "--env.world.canyon.width", "nan"], ["collect", "--env.time-limit-s", "inf"],
    ["evaluate", "heuristic", "--time-limit", "inf"], ["evaluate", "heuristic", "--canyons", "eval:"],
    ["evaluate", "heuristic", "--canyons", "eval:0,0"], ["collect", "--runs", "many"],
])
def test_a_bad_value_is_one_line_and_exit_2_with_nothing_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    out = tmp_path / "a" / "out"
    try:
        status = main([*args, "--out", str(out)])
    except SystemExit as exit_:  # argparse's own errors
        status = exit_.code
    assert status == 2
    line = _one_line(capsys)
    assert "error:" in line and "usage" not in line
    assert list(tmp_path.iterdir()) == []


def test_bag_import_refuses_more_val_runs_than_the_bag_holds(small_dataset: Path, tmp_path: Path) -> None:
    rosbag = pytest.importorskip("depthq.data.rosbag")
    bag = rosbag.export_bag(small_dataset, tmp_path / "bag", progress=False)
    with pytest.raises(ConfigError, match=r"--val-runs 999: .* holds \d+ run"):
        rosbag.import_bag(bag, tmp_path / "in", rosbag.ImportConfig(val_runs=999), progress=False)
    assert not (tmp_path / "in").exists() and not list(tmp_path.glob(".in.*"))
    with pytest.raises(ConfigError, match="--max-gap"):
        rosbag.ImportConfig(max_gap_s=float("inf"))


# --- strict JSON ------------------------------------------------------------------------------------


def test_json_is_strict_infinities_written_as_null_and_refused_when_read(tmp_path: Path) -> None:
    write_json(tmp_path / "a.json", {"time_limit_s": float("inf"), "loss": float("nan"), "n": [1.5]})
    text = (tmp_path / "a.json").read_text()
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {"time_limit_s": None, "loss": None,
                                                                          "n": [1.5]}
    (tmp_path / "b.json").write_text('{"max_gap_s": Infinity}')
    with pytest.raises(DataError, match=r"b\.json: not valid JSON"):
        read_json(tmp_path / "b.json")


# --- checksums --------------------------------------------------------------------------------------


def test_an_edited_checkpoint_config_or_sidecar_is_refused(toy_nets: dict[str, Path], tmp_path: Path) -> None:
    ckpt = shutil.copytree(toy_nets["depth"], tmp_path / "ckpt")
    load_qnet(ckpt)
    config = ckpt / "config.json"
    text = config.read_text()
    config.write_text(text.replace('"action_scale": 10.0', '"action_scale": 20.0'))
    assert config.read_text() != text
    with pytest.raises(DataError, match=r"config\.json: changed after it was written"):
        load_qnet(ckpt)
    # A record written before checksums (none in it) is read as it is.
    config.write_text(json.dumps({k: v for k, v in json.loads(text).items() if k != KEY}))
    load_qnet(ckpt)
    best = ckpt / "best.json"
    best.write_text(best.read_text().replace('"epoch": 1', '"epoch": 7'))
    with pytest.raises(DataError, match=r"best\.json: changed"):
        read_sidecar(ckpt, "best")


def test_an_edited_manifest_row_is_refused_where_training_reads_it(
    small_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for edit in ("n_frames", "swap"):
        root = tmp_path / edit
        shutil.copytree(small_dataset, root, ignore=shutil.ignore_patterns("features"))
        manifest = read_json(root / MANIFEST)
        rows = manifest["runs"]
        if edit == "n_frames":
            rows[0]["n_frames"] -= 1
        else:
            rows[0]["index"], rows[1]["index"] = rows[1]["index"], rows[0]["index"]
        write_json(root / MANIFEST, manifest)
        dataset = Dataset.open(root)
        assert dataset.verify()
        with pytest.raises(DataError, match=f"differs from its row in .*{MANIFEST} in .*(index|n_frames)"):
            for entry in dataset.entries():
                dataset.read_run(entry, images=False)
        ckpt = tmp_path / f"ckpt_{edit}"
        args = ["train", "--model", "depth", "--data", str(root), "--out", str(ckpt), "--no-progress"]
        assert main(args) == 1
        assert "differs from its row" in _one_line(capsys) and not ckpt.exists()


@pytest.mark.slow
def test_a_killed_feature_computation_is_cleaned_up_and_a_flipped_cache_byte_is_refused(
    small_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = shutil.copytree(small_dataset, tmp_path / "data", ignore=shutil.ignore_patterns("features"))
    folder = cache_dir(root, DEFAULT_TRUNK, 128)
    worker = _python("from depthq.data.manifest import Dataset\n"
                     "from depthq.train.features import load_features\n"
                     f"load_features(Dataset.open({str(root)!r}), {DEFAULT_TRUNK!r}, 128, progress=False)\n")
    deadline = time.monotonic() + 120
    while not list(folder.glob(f".{ARRAY}.*.tmp")) and worker.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    worker.send_signal(signal.SIGKILL)
    worker.wait()
    assert list(folder.glob(f".{ARRAY}.*.tmp")), "killed while writing its temporary array"
    table = load_features(Dataset.open(root), DEFAULT_TRUNK, 128, progress=False)
    assert table.computed and not list(folder.glob(".*.tmp"))
    del table
    with (folder / ARRAY).open("r+b") as f:  # one byte of the last feature: a value changes
        f.seek(-1, os.SEEK_END)
        byte = f.read(1)
        f.seek(-1, os.SEEK_END)
        f.write(bytes([byte[0] ^ 0x7C]))
    with pytest.raises(DataError, match=f"{ARRAY}: corrupted feature cache .* delete"):
        load_features(Dataset.open(root), DEFAULT_TRUNK, 128, progress=False)
    assert main(["dataset", "verify", str(root)]) == 1
    assert "corrupted feature cache" in capsys.readouterr().err
    ckpt = tmp_path / "ckpt"
    assert main(["train", "--model", "depth", "--data", str(root), "--out", str(ckpt), "--no-progress"]) == 1
    assert "corrupted feature cache" in _one_line(capsys) and not ckpt.exists()  # nothing left behind


# --- byte-identical checkpoints ---------------------------------------------------------------------


@pytest.mark.slow
def test_weight_files_are_byte_identical_across_processes() -> None:
    code = ("import hashlib, torch\nfrom depthq.checkpoint import weights_bytes\n"
            "b = weights_bytes({'w': torch.arange(6.0)}, {'epoch': '3', 'state': '{}', 'averaged': 'a+b'})\n"
            "print(hashlib.sha256(b).hexdigest())\n")
    runs = [_python(code) for _ in range(2)]
    digests = {p.communicate()[0].strip() for p in runs}
    import torch

    here = weights_bytes({"w": torch.arange(6.0)}, {"epoch": "3", "state": "{}", "averaged": "a+b"})
    assert digests == {hashlib.sha256(here).hexdigest()}


def _digests(folder: Path) -> dict[str, str]:
    """sha256 of every file but the logs (tb/, metrics.csv's seconds)."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and "tb" not in p.relative_to(folder).parts
            and p.name != "metrics.csv"}


@pytest.mark.slow
def test_a_training_resumed_after_kill_9_writes_the_same_bytes(small_dataset: Path, tmp_path: Path) -> None:
    from depthq.configio import to_dict
    from depthq.train.config import TrainConfig
    from depthq.train.trainer import train

    config = TrainConfig(model="depth", data=str(small_dataset), epochs=3, average=0.5, snapshots=(2,),
                         **FAST)
    killed = tmp_path / "killed"
    worker = _python(
        "import json\nfrom depthq.configio import from_dict\nfrom depthq.train.config import TrainConfig\n"
        "from depthq.train.trainer import train\n"
        f"config = from_dict(TrainConfig, json.loads({json.dumps(json.dumps(to_dict(config)))}))\n"
        f"train(config, {str(killed)!r}, progress=False, threads=1)\n")
    deadline = time.monotonic() + 300
    while not (killed / "last.json").is_file() and worker.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    worker.send_signal(signal.SIGKILL)
    worker.wait()
    done = read_sidecar(killed, "last")["epoch"]
    if done >= config.epochs:
        pytest.skip("the job finished before it was killed")
    train(config, killed, progress=False, threads=1)
    whole = train(config, tmp_path / "whole", progress=False, threads=1)
    assert _digests(killed) == _digests(whole)
    assert {"config.json", "best.safetensors", "last_state.safetensors", "epoch_0002.safetensors",
            "average.json"} <= set(_digests(whole))
