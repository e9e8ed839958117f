"""ROS bags, both ways, on real files: a simulated dataset out to MCAP, SQLite3 and ROS 1 and back in,
a recording cut into runs, a camera-only recording, scans of other LiDARs resampled to depthq's
360 readings, and each way a bag can be bad."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.data.runfile import JPEG_MAX_MEAN_ABS_ERROR, encode_jpeg
from depthq.data.samples import usable
from depthq.errors import ConfigError, DataError
from depthq.train.config import TrainConfig
from depthq.train.trainer import train

rosbag = pytest.importorskip("depthq.data.rosbag")
from rosbags import rosbag1, rosbag2  # noqa: E402  (after the skip: rosbags is an extra)

MS = 1_000_000  # ns


@pytest.fixture
def data(small_dataset: Path) -> Path:
    """conftest's small simulated dataset: training and validation runs (short ones besides)."""
    return small_dataset


@pytest.mark.parametrize("bag_format", ["mcap", "sqlite3", "ros1"])
def test_dataset_to_bag_to_dataset(data: Path, tmp_path: Path, bag_format: str) -> None:
    ros1 = bag_format == "ros1"
    out = tmp_path / ("bag.bag" if ros1 else "bag")
    bag = rosbag.export_bag(data, out, bag_format=bag_format, progress=False)
    assert bag.is_file() if ros1 else bag.is_dir()
    with (rosbag1 if ros1 else rosbag2).Reader(bag) as reader:  # what a ROS user sees
        types = {c.topic: c.msgtype for c in reader.connections}
        digests = {c.topic: c.digest for c in reader.connections}
        stamps = [t for _, t, _ in reader.messages()]
    if ros1:  # ROS 1's md5sums of the standard messages: rosbag play and rqt_bag accept the file
        assert digests["/scan"] == "90c7ef2dc6895d81024acba2ac42f369"
        assert digests["/camera/image_raw/compressed"] == "8f7a12909da2c9d3332d540a0977563f"
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


def _frame_msg(rgb: np.ndarray, ns: int, raw: bool, ts):
    if not raw:
        return rosbag.image_msg(encode_jpeg(rgb, 90), ns, ts)
    h, w, _ = rgb.shape
    return ts.types["sensor_msgs/msg/Image"](
        header=rosbag.header_msg(ns, "camera", ts),
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
    scan_type: str | None = "sensor_msgs/msg/LaserScan",
    raw: bool = False,
    ros1: bool = False,
) -> Path:
    """A recording as a robot makes one: frames and scans stamped in their headers, commands as sent
    (logged when sent: a Twist has no header); `scan_stamps_ms` overrides the scans' header stamps,
    `scan_type` None records no scans (a robot without a LiDAR). `raw`: uncompressed bgr8 frames on
    /camera/image_raw and TwistStamped commands, logged 100 ms late (the import must use their header
    stamps). `ros1`: a ROS 1 .bag file, in which two nodes take turns commanding (ROS 1 makes one
    connection per node)."""
    ts = rosbag.ROS1_TYPESTORE if ros1 else rosbag.TYPESTORE
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    rgb = np.zeros((24, 32, 3), np.uint8) + np.array([10, 120, 230], np.uint8)
    writer = rosbag1.Writer(path) if ros1 else rosbag2.Writer(path, version=9)
    with writer:
        image_type = "sensor_msgs/msg/Image" if raw else "sensor_msgs/msg/CompressedImage"
        cmd_type = "geometry_msgs/msg/TwistStamped" if raw else "geometry_msgs/msg/Twist"
        image = writer.add_connection(
            "/camera/image_raw" if raw else "/camera/image_raw/compressed", image_type, typestore=ts
        )
        nodes = [{"callerid": "/teleop"}, {"callerid": "/policy"}] if ros1 else [{}]
        cmd = [writer.add_connection("/cmd_vel", cmd_type, typestore=ts, **node) for node in nodes]
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        messages = [(t * MS, image, _frame_msg(rgb, t * MS, raw, ts)) for t in frames_ms]
        for t in frames_ms:
            pose = np.array([t / 1000, 0, 0])
            messages.append((t * MS, odom, rosbag.odom_msg(pose, 0.5, 0.0, t * MS, ts)))
        if scan_type is not None:
            scan = writer.add_connection("/scan", scan_type, typestore=ts)
            stamps = frames_ms if scan_stamps_ms is None else scan_stamps_ms
            for t, stamp in zip(frames_ms, stamps, strict=True):  # logged with the frame, stamped as given
                msg = (
                    rosbag.scan_msg(np.full(360, 1.5, np.float32), stamp * MS, rosbag.LidarConfig(), ts)
                    if scan_type.endswith("LaserScan")
                    else ts.types[scan_type](data="not a scan")
                )
                messages.append((t * MS, scan, msg))
        for i, (t, lin, ang) in enumerate(cmds):
            twist = rosbag.twist_msg(lin, ang, ts)
            if raw:
                stamped = ts.types[cmd_type](header=rosbag.header_msg(t * MS, "base_link", ts), twist=twist)
                messages.append(((t + 100) * MS, cmd[i % len(cmd)], stamped))
            else:
                messages.append((t * MS, cmd[i % len(cmd)], twist))
        for ns, conn, msg in sorted(messages, key=lambda m: m[0]):
            writer.write(conn, ns, serialize(msg, conn.msgtype))
    return path


@pytest.mark.parametrize(
    ("raw", "ros1"),
    [(False, False), (True, False), (True, True)],
    ids=["compressed+Twist", "bgr8+TwistStamped", "ROS 1 bgr8+TwistStamped"],
)
def test_a_recording_is_cut_where_the_robot_stops_or_the_frames_stop(
    tmp_path: Path, raw: bool, ros1: bool
) -> None:
    # 4 Hz frames; each command is sent 30 ms after its frame (the node's latency). Frames 0-9 drive,
    # 10-14 stand still, 15-24 drive, then 3 s without frames, then 25-32 drive.
    frames = [250 * i for i in range(25)] + [250 * 24 + 3000 + 250 * i for i in range(1, 9)]
    linear = [0.5] * 10 + [0.0] * 5 + [0.5] * 18
    angular = [round(0.1 * (i % 7) - 0.3, 1) for i in range(len(frames))]
    cmds = [(t + 30, v, w) for t, v, w in zip(frames, linear, angular, strict=True)]
    bag = write_bag(tmp_path / ("rec.bag" if ros1 else "rec"), frames, cmds, raw=raw, ros1=ros1)
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

    still = write_bag(tmp_path / "still.bag", frames, [(t + 30, 0.0, 0.0) for t in frames], ros1=True)
    with pytest.raises(ConfigError, match=r"still.bag: no run found \(no frame while the robot drove, with"):
        rosbag.import_bag(still, out, progress=False)
    assert main(["bag", "import", str(still), "--out", str(out)]) == 2

    (tmp_path / "empty").mkdir()
    for neither in (good / "metadata.yaml", tmp_path / "empty"):  # a file not named .bag; no metadata.yaml
        with pytest.raises(ConfigError, match=f"{neither}: neither a ROS 1 bag .* nor a rosbag2 bag"):
            rosbag.import_bag(neither, out, progress=False)
        assert main(["bag", "import", str(neither), "--out", str(out)]) == 2

    cut = rosbag.export_bag(data, tmp_path / "cut", progress=False)
    (mcap,) = cut.glob("*.mcap")
    cut1 = write_bag(tmp_path / "cut1.bag", frames, cmds, ros1=True)
    for path, kind in ((mcap, "rosbag2"), (cut1, "rosbag1")):
        with open(path, "r+b") as f:
            f.truncate(path.stat().st_size // 2)
        bag = cut if kind == "rosbag2" else cut1
        with pytest.raises(DataError, match=f"{bag.name}: not a readable {kind} bag"):
            rosbag.import_bag(bag, out, progress=False)
        assert main(["bag", "import", str(bag), "--out", str(out)]) == 1
    assert _nothing_left(tmp_path, out)


def test_a_bad_export_format_exits_2_and_writes_nothing(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bag"
    assert main(["bag", "export", str(data), "--out", str(out), "--format", "ros2"]) == 2
    assert "--format must be one of mcap, sqlite3, ros1, got 'ros2'" in capsys.readouterr().err
    assert main(["bag", "export", str(data), "--out", str(out), "--format", "ros1"]) == 2  # not *.bag
    assert "a ROS 1 bag is one file named *.bag" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_camera_only_recording_imports_with_an_empty_scan_topic(tmp_path: Path) -> None:
    frames = [250 * i for i in range(30)]
    cmds = [(t + 30, 0.5, 0.1) for t in frames]
    bag = write_bag(tmp_path / "camera.bag", frames, cmds, scan_type=None, ros1=True)
    out = tmp_path / "data"
    missing = r"no topic /scan \(--scan-topic\); the bag has /camera/image_raw/compressed, /cmd_vel, /odom$"
    with pytest.raises(ConfigError, match=missing):
        rosbag.import_bag(bag, out, progress=False)
    assert main(["bag", "import", str(bag), "--out", str(out)]) == 2
    assert _nothing_left(tmp_path, out)

    assert main(["bag", "import", str(bag), "--out", str(out), "--scan-topic", ""]) == 0
    dataset = Dataset.open(out)
    assert dataset.verify() == [] and dataset.config["source"] == "rosbag1"
    (entry,) = dataset.entries()
    run = dataset.read_run(entry)
    assert run.n_frames == 30 and run.scans.shape == (30, 360) and run.bins.shape == (30, 26)
    assert np.isposinf(run.scans).all() and np.isnan(run.bins).all()  # nothing measured
    assert np.allclose(run.actions[:-1], 0.1) and np.allclose(run.poses[:, 0], np.asarray(frames) / 1000)


@pytest.mark.slow  # a toy labeller (the default, monodepth), a labelling and a training: ~10 s
def test_a_camera_only_recording_trains_on_labels_from_its_own_camera(tmp_path: Path) -> None:
    # Two drives 10 s apart (each 30 frames at 4 Hz): one train run, one val run; no LiDAR anywhere.
    frames = [250 * i for i in range(30)] + [20_000 + 250 * i for i in range(30)]
    bag = write_bag(tmp_path / "camera.bag", frames, [(t + 30, 0.5, 0.1) for t in frames], scan_type=None,
                    ros1=True)
    data, labeller, net = tmp_path / "data", tmp_path / "labeller", tmp_path / "net"
    assert main(["bag", "import", str(bag), "--out", str(data), "--scan-topic", ""]) == 0
    assert main(["labeller", "--data", str(data), "--out", str(labeller), "--steps", "3", "--batch-size", "2",
                 "--pool-frames", "2", "--width", "4", "--no-progress"]) == 0  # camera and odometry only
    assert main(["label", str(data), "--from", "camera", "--labeller", str(labeller), "--no-progress"]) == 0
    dataset = Dataset.open(data)
    for entry in dataset.entries():
        run = dataset.read_run(entry, images=False)
        assert np.isnan(run.bins).all() and run.camera is not None  # no LiDAR, labels from the camera
        assert np.isfinite(run.camera.bins).all() and ((run.camera.bins >= 0) & (run.camera.bins <= 2)).all()
    assert main(["train", "--model", "depth", "--data", str(data), "--labels", "camera", "--epochs", "1",
                 "--train-batches", "2", "--val-batches", "1", "--batch-size", "4", "--out", str(net),
                 "--no-progress"]) == 0
    assert (net / "last.safetensors").is_file()


def _laser(angle_min: float, increment_deg: float, ranges: np.ndarray):
    """A LaserScan as a driver publishes it and a bag gives it back (float32 angles): beam j at
    angle_min + j · increment, range 0.12 to 3.5 m."""
    ts, msgtype = rosbag.TYPESTORE, "sensor_msgs/msg/LaserScan"
    increment = np.deg2rad(increment_deg)
    msg = ts.types[msgtype](
        header=rosbag.header_msg(0, "laser"),
        angle_min=angle_min,
        angle_max=angle_min + increment * (len(ranges) - 1),
        angle_increment=increment,
        time_increment=0.0,
        scan_time=0.0,
        range_min=0.12,
        range_max=3.5,
        ranges=np.asarray(ranges, np.float32),
        intensities=np.zeros(0, np.float32),
    )
    return ts.deserialize_cdr(ts.serialize_cdr(msg, msgtype), msgtype)


NO = -1  # no beam within half a spacing: the bearing reads 0 (invalid)
BEARING = np.arange(360)


@pytest.mark.parametrize(
    ("n_beams", "angle_min", "increment_deg", "beam_of_bearing"),
    [
        (360, 0.0, 1.0, BEARING),  # the LDS-01: 0° to 359° counter-clockwise
        (720, 0.0, 0.5, 2 * BEARING),  # 0.5° apart: every other beam
        (360, -np.pi, 1.0, (BEARING + 180) % 360),  # −180° to 179°: beam 180 looks ahead
        (361, -np.pi, 1.0, (BEARING + 180) % 360),  # −180° to +180°: beams 0 and 360 look back; the first
        (180, 0.0, 2.0, np.r_[BEARING[:359] // 2, 0]),  # 2° apart: an odd bearing takes the first of two
        (181, np.pi / 2, -1.0, np.r_[90 - BEARING[:91], [NO] * 179, 450 - BEARING[270:]]),  # clockwise ±90°
        (1081, -0.75 * np.pi, 0.25, np.r_[540 + 4 * BEARING[:136], [NO] * 89, 4 * BEARING[225:] - 900]),
    ],
    ids=["360-ccw", "720-half-degree", "360-from-minus-pi", "361-minus-pi-to-pi", "180-two-degrees",
         "181-clockwise-front", "1081-270-degrees"],
)
def test_a_laser_scan_is_resampled_to_the_nearest_beam_of_each_degree(
    n_beams: int, angle_min: float, increment_deg: float, beam_of_bearing: np.ndarray
) -> None:
    ranges = (1 + np.arange(n_beams) / 1000).astype(np.float32)  # beam j reads 1 + j / 1000 m
    rays = rosbag._scan_to_rays(_laser(angle_min, increment_deg, ranges))
    assert rays.shape == (360,) and rays.dtype == np.float32
    expected = np.where(beam_of_bearing == NO, 0.0, ranges[beam_of_bearing]).astype(np.float32)
    assert np.array_equal(rays, expected)


def test_invalid_readings_read_as_the_lds01_reports_them() -> None:
    ranges = np.full(360, 2.0, np.float32)
    ranges[:8] = [np.nan, 0.05, -np.inf, 0.0, 0.12, 3.5, 3.6, np.inf]
    rays = rosbag._scan_to_rays(_laser(0.0, 1.0, ranges))
    # NaN, below range_min (−inf and 0 too) → 0, invalid; range_min and range_max themselves are kept;
    # beyond range_max (+inf too) → inf, no return
    assert np.array_equal(rays[:8], np.array([0, 0, 0, 0, 0.12, 3.5, np.inf, np.inf], np.float32))
    assert (rays[8:] == 2.0).all()
    assert np.array_equal(rosbag._scan_to_rays(_laser(0.0, 1.0, np.zeros(0))), np.zeros(360, np.float32))


def test_commands_logged_in_one_clock_tick_import_the_later_one(tmp_path: Path) -> None:
    """A Twist's stamp is when the recorder logged it; on a simulated /clock two commands can share one
    tick (a decision and the shutdown's zero twist in `depthq ros sim`'s 5 ms ticks). Equal log times
    are not out of order: the later message is the command in force. Decreasing ones still are."""
    frames = [250 * i for i in range(30)]
    cmds = [(t + 30, 0.5, 0.0) for t in frames]
    cmds.insert(11, (frames[10] + 30, 0.5, 0.7))  # logged in the same tick as frame 10's command, after it
    bag = write_bag(tmp_path / "ties", frames, cmds)
    dataset = rosbag.import_bag(bag, tmp_path / "data", rosbag.ImportConfig(val_runs=0), progress=False)
    actions = dataset.read_run(dataset.entries()[0]).actions
    assert actions[10] == pytest.approx(0.7) and actions[9] == 0 and actions[11] == 0
