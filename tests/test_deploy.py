"""ONNX export: the real exporter, onnx.checker and onnxruntime against the torch policy."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from conftest import assert_video
from PIL import Image

from depthq.blocks.trunk import preprocess
from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.deploy.onnx_export import FrameResize, export_onnx
from depthq.deploy.robot import LINEAR_SPEED, decode_frame, twist_for_frame
from depthq.errors import ConfigError, DataError
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.policies.onnx import OnnxPolicy
from depthq.policies.qnet import QNetPolicy

pytestmark = pytest.mark.slow  # every test here needs two trained networks (conftest's toy_nets)


@pytest.fixture
def trained(small_dataset: Path, toy_nets: dict[str, Path]) -> dict[str, Path]:
    """conftest's small dataset and its Depth-Q-Net and Coll-Q-Net trained on it for two batches."""
    return {"data": small_dataset, **toy_nets}


def _val_frames(data: Path) -> list[np.ndarray]:
    dataset = Dataset.open(data)
    frames = []
    for entry in dataset.entries("val"):
        with dataset.reader(entry) as reader:
            frames += [reader.image(t) for t in range(entry.n_frames)]
    return frames


def test_resize_in_the_graph_is_preprocess_to_the_bit(trained: dict[str, Path]) -> None:
    frames = _val_frames(trained["data"])[:10]
    resize = FrameResize(frames[0].shape[:2], 128)
    for frame in frames:
        assert torch.equal(resize(torch.from_numpy(frame)), preprocess(frame))
    other = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)  # another camera
    assert torch.equal(FrameResize((240, 320), 96)(torch.from_numpy(other)), preprocess(other, 96))


@pytest.mark.parametrize("model", ["depth", "coll"])
def test_onnx_predictions_equal_torch(trained: dict[str, Path], tmp_path: Path, model: str) -> None:
    path = export_onnx(trained[model], tmp_path / "onnx")
    onnx.checker.check_model(onnx.load(path), full_check=True)
    meta = {p.key: p.value for p in onnx.load(path).metadata_props}
    assert meta["depthq.kind"] == model and meta["depthq.actions"] == "[-1.0, 0.0, 1.0]"
    assert '"trunk": "efficientnet_lite0_columns"' in meta["depthq.config"]

    onnx_policy, torch_policy = OnnxPolicy(path), QNetPolicy.from_checkpoint(trained[model])
    frames = _val_frames(trained["data"])
    worst = max(np.abs(onnx_policy.values(f) - torch_policy.values(f)).max() for f in frames)
    assert worst < 1e-4, worst
    assert onnx_policy.values(frames[0]).shape == ((3, 26) if model == "depth" else (3,))
    with pytest.raises(ConfigError, match=r"uint8 frame \(308, 410, 3\)"):
        onnx_policy.values(frames[0][:100])


def test_onnx_policy_drives_as_the_checkpoint(trained: dict[str, Path], tmp_path: Path) -> None:
    path = export_onnx(trained["depth"], tmp_path / "onnx")
    config = EvalConfig(canyons=parse_canyon_set("val:1000-1001"), time_limit_s=6.0)
    rows = {}
    for name, spec in (("torch", str(trained["depth"])), ("onnx", f"onnx:{path}")):
        evaluate(spec, tmp_path / name, config, workers=1, progress=False)
        with (tmp_path / name / "runs.csv").open() as f:
            rows[name] = [(r["canyon"], r["distance"], r["steps"], r["end_reason"])
                          for r in csv.DictReader(f)]
    assert rows["onnx"] == rows["torch"]
    described = json.loads((tmp_path / "onnx" / "summary.json").read_text())["policy"]
    assert described["runtime"].startswith("onnxruntime ") and described["policy"] == f"ONNX:{path.stem}"


def test_an_onnx_session_runs_the_threads_asked_for(trained: dict[str, Path], tmp_path: Path) -> None:
    path = export_onnx(trained["coll"], tmp_path / "onnx")
    one, default = OnnxPolicy(path, threads=1), OnnxPolicy(path)
    assert one.session.get_session_options().intra_op_num_threads == 1
    frames = _val_frames(trained["data"])[:5]
    for frame in frames:  # more threads may sum in another order: the same values but for the last bits
        np.testing.assert_allclose(one.values(frame), default.values(frame), atol=1e-6)


def test_bench_times_torch_and_onnx_on_the_same_frames(
    trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = export_onnx(trained["depth"], tmp_path / "onnx")
    spec = ["--policy", str(trained["depth"]), "--policy", f"onnx:{path}"]
    assert main(["bench", "policy", *spec, "--decisions", "5", "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert [p["policy"] for p in result["policies"]] == [f"DQN:{trained['depth'].name}", f"ONNX:{path.stem}"]
    assert all(0 < p["ms_median"] <= p["ms_p90"] for p in result["policies"])


def test_evaluation_video_shows_the_collision_probabilities(trained: dict[str, Path], tmp_path: Path) -> None:
    config = EvalConfig(canyons=parse_canyon_set("val:1000"), time_limit_s=4.0)
    result = evaluate(str(trained["coll"]), tmp_path, config, workers=1, progress=False)
    assert_video(tmp_path / "video.mp4", result["runs"][0]["steps"], config.env.world.decision_hz)


def test_export_cli_refuses_bad_input_and_writes_nothing(trained: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert main(["export", str(tmp_path / "missing"), "--out", str(out)]) == 2
    assert main(["export", str(trained["depth"]), "--out", str(out), "--frame-size", "308"]) == 2
    assert main(["export", str(trained["depth"]), "--out", str(out), "--weights", "worst"]) == 2
    assert not out.exists()
    with pytest.raises(ConfigError, match="no such file"):
        OnnxPolicy(tmp_path / "absent.onnx")


def test_robot_step_decodes_a_compressed_frame_and_steers(trained: dict[str, Path], tmp_path: Path) -> None:
    path = export_onnx(trained["coll"], tmp_path / "onnx")
    onnx_policy, torch_policy = OnnxPolicy(path), QNetPolicy.from_checkpoint(trained["coll"])
    for frame in _val_frames(trained["data"])[:5]:
        buffer = io.BytesIO()
        Image.fromarray(frame).save(buffer, format="JPEG", quality=90)  # as a camera driver sends it
        decoded = decode_frame(buffer.getvalue())
        assert decoded.shape == frame.shape and np.abs(decoded.astype(int) - frame).mean() < 3
        twist = twist_for_frame(onnx_policy, decoded)
        assert twist.linear_x == LINEAR_SPEED and twist.angular_z == torch_policy.act({"image": decoded})
    with pytest.raises(DataError, match="not a JPEG or PNG"):
        decode_frame(b"\x00" * 100)
