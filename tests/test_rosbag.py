"""ROS 2 bags, both ways, on real files: a simulated dataset out to MCAP and SQLite3 and back in,
a recording cut into runs, and each way a bag can be bad."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.data.labels import usable
from depthq.data.manifest import Dataset
from depthq.data.runfile import JPEG_MAX_MEAN_ABS_ERROR, encode_jpeg
from depthq.errors import ConfigError, DataError
from depthq.train.config import TrainConfig
from depthq.train.trainer import train

rosbag = pytest.importorskip("depthq.data.rosbag")
from rosbags.rosbag2 import Reader, Writer  # noqa: E402  (after the skip: rosbags is an extra)

MS = 1_000_000  # ns


@pytest.fixture
def data(small_dataset: Path) -> Path:
    """conftest's small simulated dataset: training and validation runs (short ones besides)."""
    return small_dataset


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_dataset_to_bag_to_dataset(data: Path, tmp_path: Path, storage: str) -> None:
    bag = rosbag.export_bag(data, tmp_path / "bag", storage=storage, progress=False)
    with Reader(bag) as reader:  # what a ROS user sees
        types = {c.topic: c.msgtype for c in reader.connections}
        stamps = [t for _, t, _ in reader.messages()]
    assert types == {
        "/camera/image_raw/compressed": "sensor_msgs/msg/CompressedImage",
        "/scan": "sensor_msgs/msg/LaserScan",
        "/cmd_vel": "geometry_msgs/msg/Twist",
        "/odom": "nav_msgs/msg/Odometry",
    }
    original = Dataset.open(data)
    assert len(stamps) == 4 * sum(e.n_frames for e in original.entries())

    n_val = len(original.entries("val"))
    imported = rosbag.import_bag(bag, tmp_path / "back", rosbag.ImportConfig(val_runs=n_val), progress=False)
    assert imported.verify() == []
    assert [(e.split, e.index, e.n_frames) for e in imported.entries()] == [
        (e.split, e.index, e.n_frames) for e in original.entries()
    ]
    for a_entry, b_entry in zip(original.entries(), imported.entries(), strict=True):
        a, b = original.read_run(a_entry), imported.read_run(b_entry)
        assert np.array_equal(a.scans, b.scans)
        assert np.array_equal(a.bins, b.bins, equal_nan=True)
        assert np.array_equal(a.actions, b.actions, equal_nan=True)
        assert np.array_equal(a.poses[:, :2], b.poses[:, :2])
        assert np.abs(np.angle(np.exp(1j * (a.poses[:, 2] - b.poses[:, 2])))).max() < 1e-5
        assert np.array_equal(a.times - a.times[0], b.times)
        assert np.abs(a.images.astype(int) - b.images).mean() < JPEG_MAX_MEAN_ABS_ERROR
        assert b_entry.end_reason == "stop" and b_entry.canyon_split == "recorded"


@pytest.mark.slow
def test_an_imported_dataset_trains(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag, back = tmp_path / "bag", tmp_path / "back"
    assert main(["bag", "export", str(data), "--out", str(bag)]) == 0
    assert main(["bag", "import", str(bag), "--out", str(back)]) == 0
    assert main(["dataset", "stats", str(back)]) == 0
    runs = Dataset.open(data).entries()  # exported in order; the import's last run is its one val run
    n_usable = sum(usable(e) for e in runs[:-1])
    assert f"{len(runs) - 1} train runs ({n_usable} usable)" in capsys.readouterr().out
    config = TrainConfig(
        model="depth", data=str(back), epochs=1, train_batches=2, val_batches=1, batch_size=8
    )
    assert (train(config, tmp_path / "net", progress=False) / "best.safetensors").is_file()


def _twist(linear: float, angular: float):
    return rosbag.twist_msg(linear, angular)


def _frame_msg(rgb: np.ndarray, ns: int, raw: bool):
    if not raw:
        return rosbag.image_msg(encode_jpeg(rgb, 90), ns)
    h, w, _ = rgb.shape
    return rosbag.TYPESTORE.types["sensor_msgs/msg/Image"](
        header=rosbag.header_msg(ns, "camera"),
        height=h,
        width=w,
        encoding="bgr8",
        is_bigendian=0,
        step=w * 3,
        data=rgb[..., ::-1].reshape(-1).copy(),
    )


def write_bag(
    path: Path,
    frames_ms: list[int],
    cmds: list[tuple[int, float, float]],
    scan_stamps_ms: list[int] | None = None,
    scan_type: str = "sensor_msgs/msg/LaserScan",
    raw: bool = False,
) -> Path:
    """A recording as a robot makes one: frames and scans stamped in their headers, commands as sent
    (logged when sent: a Twist has no header); `scan_stamps_ms` overrides the scans' header stamps.
    `raw`: uncompressed bgr8 frames on /camera/image_raw and TwistStamped commands, logged 100 ms
    late (the import must use their header stamps)."""
    ts = rosbag.TYPESTORE
    rgb = np.zeros((24, 32, 3), np.uint8) + np.array([10, 120, 230], np.uint8)
    with Writer(path, version=9) as writer:
        if raw:
            image = writer.add_connection("/camera/image_raw", "sensor_msgs/msg/Image", typestore=ts)
            cmd = writer.add_connection("/cmd_vel", "geometry_msgs/msg/TwistStamped", typestore=ts)
        else:
            image = writer.add_connection(
                "/camera/image_raw/compressed", "sensor_msgs/msg/CompressedImage", typestore=ts
            )
            cmd = writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=ts)
        scan = writer.add_connection("/scan", scan_type, typestore=ts)
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        messages = [(t * MS, image, _frame_msg(rgb, t * MS, raw)) for t in frames_ms]
        stamps = frames_ms if scan_stamps_ms is None else scan_stamps_ms
        for t, stamp in zip(frames_ms, stamps, strict=True):  # logged with the frame, stamped as given
            msg = (
                rosbag.scan_msg(np.full(360, 1.5, np.float32), stamp * MS, rosbag.LidarConfig())
                if scan_type.endswith("LaserScan")
                else ts.types[scan_type](data="not a scan")
            )
            messages.append((t * MS, scan, msg))
            messages.append((t * MS, odom, rosbag.odom_msg(np.array([t / 1000, 0, 0]), 0.5, 0.0, t * MS)))
        for t, lin, ang in cmds:
            if raw:
                stamped = ts.types["geometry_msgs/msg/TwistStamped"](
                    header=rosbag.header_msg(t * MS, "base_link"), twist=_twist(lin, ang)
                )
                messages.append(((t + 100) * MS, cmd, stamped))
            else:
                messages.append((t * MS, cmd, _twist(lin, ang)))
        for ns, conn, msg in sorted(messages, key=lambda m: m[0]):
            writer.write(conn, ns, ts.serialize_cdr(msg, conn.msgtype))
    return path


@pytest.mark.parametrize("raw", [False, True], ids=["compressed+Twist", "bgr8+TwistStamped"])
def test_a_recording_is_cut_where_the_robot_stops_or_the_frames_stop(tmp_path: Path, raw: bool) -> None:
    # 4 Hz frames; each command is sent 30 ms after its frame (the node's latency). Frames 0-9 drive,
    # 10-14 stand still, 15-24 drive, then 3 s without frames, then 25-32 drive.
    frames = [250 * i for i in range(25)] + [250 * 24 + 3000 + 250 * i for i in range(1, 9)]
    linear = [0.5] * 10 + [0.0] * 5 + [0.5] * 18
    angular = [round(0.1 * (i % 7) - 0.3, 1) for i in range(len(frames))]
    cmds = [(t + 30, v, w) for t, v, w in zip(frames, linear, angular, strict=True)]
    bag = write_bag(tmp_path / "rec", frames, cmds, raw=raw)
    topics = rosbag.Topics(image="/camera/image_raw") if raw else rosbag.Topics()
    config = rosbag.ImportConfig(topics=topics, val_runs=1)
    dataset = rosbag.import_bag(bag, tmp_path / "data", config, progress=False)
    runs = [dataset.read_run(e) for e in dataset.entries()]
    # run 1: frames 0-10 (10 is where it stood); run 2: 15-24 (24 is the last before the gap); run 3: 25-32
    assert [(r.meta.split, r.n_frames) for r in runs] == [("train", 11), ("train", 10), ("val", 8)]
    assert np.allclose(runs[0].actions[:-1], angular[:10])
    assert np.allclose(runs[1].actions[:-1], angular[15:24])
    assert np.allclose(runs[2].actions[:-1], angular[25:32])
    assert np.allclose(runs[1].times, np.arange(10) * 0.25)
    assert np.allclose(runs[1].bins, 1.5)
    assert np.allclose(runs[2].poses[:, 0], np.asarray(frames[25:]) / 1000)
    assert np.abs(runs[0].images[0, 12, 16].astype(int) - [10, 120, 230]).max() <= 3  # RGB, not BGR


def _nothing_left(parent: Path, out: Path) -> bool:
    return not out.exists() and not [p for p in parent.iterdir() if p.name.startswith(f".{out.name}")]


def test_a_bad_bag_is_named_and_leaves_nothing(tmp_path: Path, data: Path) -> None:
    frames = [250 * i for i in range(30)]
    cmds = [(t + 30, 0.5, 0.0) for t in frames]
    out = tmp_path / "out"

    good = write_bag(tmp_path / "good", frames, cmds)
    with pytest.raises(
        ConfigError, match=r"no topic /camera/image_raw \(--image-topic\); the bag has .*/cmd_vel"
    ):
        rosbag.import_bag(good, out, rosbag.ImportConfig(topics=rosbag.Topics(image="/camera/image_raw")))
    assert main(["bag", "import", str(good), "--out", str(out), "--scan-topic", "/lidar"]) == 2

    odd = write_bag(tmp_path / "odd", frames, cmds, scan_type="std_msgs/msg/String")
    with pytest.raises(DataError, match="topic /scan has message type std_msgs/msg/String"):
        rosbag.import_bag(odd, out, progress=False)

    late = write_bag(tmp_path / "late", frames, cmds, scan_stamps_ms=[*frames[:10], 100, *frames[11:]])
    with pytest.raises(DataError, match="stamps on /scan are not increasing: message 10"):
        rosbag.import_bag(late, out, progress=False)

    cut = rosbag.export_bag(data, tmp_path / "cut", progress=False)
    (mcap,) = cut.glob("*.mcap")
    with open(mcap, "r+b") as f:
        f.truncate(mcap.stat().st_size // 2)
    with pytest.raises(DataError, match="cut: not a readable rosbag2 bag"):
        rosbag.import_bag(cut, out, progress=False)
    assert main(["bag", "import", str(cut), "--out", str(out)]) == 1
    assert _nothing_left(tmp_path, out)

    with pytest.raises(ConfigError, match="--storage must be one of"):
        rosbag.export_bag(data, tmp_path / "x", storage="bag")
    assert _nothing_left(tmp_path, tmp_path / "x")


def test_another_lidar_is_resampled_to_one_ray_per_degree() -> None:
    # an LDS-02-like scan: 720 rays from −180°, 0.5° apart; ray j reads 1 + j / 1000 m
    step = np.deg2rad(0.5)
    ranges = (1 + np.arange(720) / 1000).astype(np.float32)
    ranges[[0, 1, 2]] = [np.nan, 0.05, 9.0]  # NaN, below range_min, beyond range_max
    msg = rosbag.scan_msg(np.zeros(360, np.float32), 0, rosbag.LidarConfig())
    msg = type(msg)(**{**msg.__dict__, "angle_min": -np.pi, "angle_increment": step, "ranges": ranges})
    rays = rosbag._scan_to_rays(msg)
    assert rays.shape == (360,) and rays.dtype == np.float32
    assert rays[0] == ranges[360] and rays[90] == ranges[540] and rays[270] == ranges[180]
    assert rays[180] == 0.0  # ray 0 (−180°): NaN → invalid
    assert np.isinf(rays[181])  # ray 2 (−179°): beyond range_max → no return
