"""ROS 2 bags in and out of a dataset (rosbag2, MCAP or SQLite3, read and written by `rosbags`).

Export: every run of a dataset, one after the other, as the topics a TurtleBot3 publishes:

    /camera/image_raw/compressed  sensor_msgs/CompressedImage  the run's JPEG frames, unchanged
    /scan                         sensor_msgs/LaserScan        360 rays from 0° counter-clockwise, 1° apart
    /cmd_vel                      geometry_msgs/Twist          0.5 m/s and the action, at the frame's stamp;
                                                               zero at a run's last frame (the robot stops)
    /odom                         nav_msgs/Odometry            the pose (x, y, yaw) and the command

Stamps are `EPOCH_S` + the run's own times; runs are `RUN_GAP_S` apart. An imported run's times start
at 0 at its first frame, and its heading is unwrapped (continuous) over the whole recording.

Import: a robot's recording becomes runs. Frame t is each image; its scan is the one nearest to
its stamp; its action is the yaw rate of the last command sent before frame t + 1 was taken (the
command that moved the robot between the two frames); its pose the odometry nearest to its stamp.
A run ends where the robot stands (linear speed 0), where frames are more than `max_gap_s` apart,
or where no scan lies within `max_gap_s` / 2 of a frame. Runs keep the dataset layout of
`depthq.data.manifest` with `canyon_split="recorded"` and `end_reason="stop"`; the last
`val_runs` runs form the `val` split. The dataset is written in a hidden sibling folder and renamed
into place when complete, so a bad bag leaves nothing behind.
"""

from __future__ import annotations

import io
import math
import os
import shutil
import struct
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import astuple, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, UnidentifiedImageError
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from tqdm import tqdm

from depthq.configio import to_dict
from depthq.data.manifest import Dataset
from depthq.data.run import Run, RunMeta
from depthq.data.runfile import JPEG_QUALITY
from depthq.errors import ConfigError, DataError
from depthq.sim.sensors import N_RAYS, BinConfig, LidarConfig, depth_bins

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)  # the TurtleBot3's distribution; these messages never changed
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
EPOCH_S = 1_600_000_000  # the exported bag's first stamp (2020-09-13): equal datasets, equal bags
RUN_GAP_S = 10.0  # silence between two exported runs: longer than any import's max_gap_s
STOPPED = 1e-3  # m/s: a command slower than this stands the robot still


@dataclass(frozen=True)
class Topics:
    """Where the streams are; the defaults are the TurtleBot3's (`odom=""` imports without poses)."""

    image: str = "/camera/image_raw/compressed"
    scan: str = "/scan"
    cmd: str = "/cmd_vel"
    odom: str = "/odom"


IMAGE_TYPES = ("sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/Image")
SCAN_TYPES = ("sensor_msgs/msg/LaserScan",)
CMD_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")
ODOM_TYPES = ("nav_msgs/msg/Odometry",)


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def header_msg(ns: int, frame_id: str) -> Any:
    t = TYPESTORE.types
    stamp = t["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    return t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def _vector(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return TYPESTORE.types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


# ----------------------------------------------------------------------------------------- export


def export_bag(data: Path, out: Path, storage: str = "mcap", progress: bool = True) -> Path:
    """Write every run of the dataset `data` as one rosbag2 folder `out` (see the module docstring)."""
    if storage not in STORAGES:
        raise ConfigError(f"--storage must be one of {sorted(STORAGES)}, got {storage!r}")
    out = Path(out)
    if out.exists():
        raise ConfigError(f"{out}: exists; a bag is written to a new folder")
    dataset = Dataset.open(Path(data))
    speed = float(dataset.config.get("env", {}).get("world", {}).get("speed", 0.5))
    lidar = LidarConfig()
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        writer = Writer(staging / out.name, version=9, storage_plugin=STORAGES[storage])
        with writer:
            types = (
                "sensor_msgs/msg/CompressedImage",
                "sensor_msgs/msg/LaserScan",
                "geometry_msgs/msg/Twist",
                "nav_msgs/msg/Odometry",
            )
            conns = [
                writer.add_connection(topic, msgtype, typestore=TYPESTORE)
                for topic, msgtype in zip(astuple(Topics()), types, strict=True)
            ]
            start_ns = EPOCH_S * 1_000_000_000
            for entry in tqdm(dataset.entries(), desc="bag export", unit="run", disable=not progress):
                with dataset.reader(entry) as reader:
                    run = reader.run(images=False)
                    for t in range(run.n_frames):
                        ns = start_ns + round(float(run.times[t]) * 1e9)
                        action = 0.0 if t == run.n_frames - 1 else float(run.actions[t])
                        linear = 0.0 if t == run.n_frames - 1 else speed
                        msgs = (
                            image_msg(reader.jpeg(t), ns),
                            scan_msg(run.scans[t], ns, lidar),
                            twist_msg(linear, action),
                            odom_msg(run.poses[t], linear, action, ns),
                        )
                        for conn, msg in zip(conns, msgs, strict=True):
                            writer.write(conn, ns, TYPESTORE.serialize_cdr(msg, conn.msgtype))
                start_ns += round((float(run.times[-1]) + RUN_GAP_S) * 1e9)
        os.replace(staging / out.name, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out


def image_msg(jpeg: bytes, ns: int) -> Any:
    return TYPESTORE.types["sensor_msgs/msg/CompressedImage"](
        header=header_msg(ns, "camera_rgb_optical_frame"), format="jpeg", data=np.frombuffer(jpeg, np.uint8)
    )


def scan_msg(scan: np.ndarray, ns: int, lidar: LidarConfig) -> Any:
    step = 2 * math.pi / N_RAYS
    return TYPESTORE.types["sensor_msgs/msg/LaserScan"](
        header=header_msg(ns, "base_scan"),
        angle_min=0.0,
        angle_max=step * (N_RAYS - 1),
        angle_increment=step,
        time_increment=0.0,
        scan_time=0.0,
        range_min=lidar.range_min,
        range_max=lidar.range_max,
        ranges=np.asarray(scan, np.float32),
        intensities=np.zeros(0, np.float32),
    )


def twist_msg(linear: float, angular: float) -> Any:
    return TYPESTORE.types["geometry_msgs/msg/Twist"](linear=_vector(x=linear), angular=_vector(z=angular))


def odom_msg(pose: np.ndarray, linear: float, angular: float, ns: int) -> Any:
    t = TYPESTORE.types
    x, y, yaw = (float(v) for v in pose)
    orientation = t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    pose_msg = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=orientation
    )
    return t["nav_msgs/msg/Odometry"](
        header=header_msg(ns, "odom"),
        child_frame_id="base_footprint",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose_msg, covariance=np.zeros(36)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=twist_msg(linear, angular), covariance=np.zeros(36)
        ),
    )


# ----------------------------------------------------------------------------------------- import


@dataclass(frozen=True)
class ImportConfig:
    """How a recording is cut into runs; stored as the imported dataset's config."""

    topics: Topics = Topics()
    max_gap_s: float = 1.0
    val_runs: int = 1
    jpeg_quality: int = JPEG_QUALITY

    def __post_init__(self) -> None:
        if not self.max_gap_s > 0:
            raise ConfigError(f"--max-gap must be > 0 s, got {self.max_gap_s}")
        if self.val_runs < 0:
            raise ConfigError(f"--val-runs must be >= 0, got {self.val_runs}")
        for name in ("image", "scan", "cmd"):
            if not getattr(self.topics, name).startswith("/"):
                raise ConfigError(
                    f"--{name}-topic must be a ROS topic name starting with '/', "
                    f"got {getattr(self.topics, name)!r}"
                )


@dataclass(frozen=True)
class _Streams:
    """Everything but the images, read in a first pass: stamps in ns, sorted as recorded."""

    frame_ns: np.ndarray  # (F,) image stamps
    scan_ns: np.ndarray  # (S,)
    scans: np.ndarray  # (S, 360) float32 in depthq's convention (0 invalid, inf no return)
    odom_ns: np.ndarray  # (O,)
    poses: np.ndarray  # (O, 3)
    frame_cmds: np.ndarray  # (F, 2) linear x, angular z of the command in force after each frame


def import_bag(bag: Path, out: Path, config: ImportConfig = ImportConfig(), progress: bool = True) -> Dataset:
    """Turn the recording `bag` into a new dataset folder `out` (see the module docstring)."""
    bag, out = Path(bag), Path(out)
    if out.exists():
        raise ConfigError(f"{out}: exists; a bag is imported into a new folder")
    if not bag.exists():
        raise ConfigError(f"{bag}: no such bag")
    with _open(bag) as reader:
        conns = _connections(bag, reader, config.topics)
        streams = _read_streams(bag, reader, conns)
        cuts = _cut_runs(streams, config.max_gap_s)
        if not cuts:
            raise DataError(
                f"{bag}: no run found (no frame while the robot drove, with a scan within "
                f"{config.max_gap_s / 2:g} s)"
            )
        out.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
        try:
            record = {"source": "rosbag2", "bag": bag.name, **to_dict(config)}
            dataset = Dataset.create(staging, record, seed=0)
            n_val = min(config.val_runs, len(cuts) - 1)
            bar = tqdm(total=len(cuts), desc="bag import", unit="run", disable=not progress)
            for position, (first, last, images) in enumerate(_runs_with_images(bag, reader, conns, cuts)):
                is_val = position >= len(cuts) - n_val
                index = position - (len(cuts) - n_val) if is_val else position
                dataset.add_run(
                    _make_run(streams, first, last, images, "val" if is_val else "train", index, position),
                    config.jpeg_quality,
                )
                bar.update(1)
            bar.close()
            os.replace(staging, out)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return Dataset.open(out)


@contextmanager
def _open(bag: Path) -> Iterator[Reader]:
    """rosbags' Reader with every way a bag can be unreadable turned into a DataError naming it."""
    try:
        reader = Reader(bag)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError) as err:
        raise DataError(f"{bag}: not a readable rosbag2 bag ({err})") from err
    try:
        yield reader
    finally:
        reader.close()


def _connections(bag: Path, reader: Reader, topics: Topics) -> dict[str, Any]:
    """The connection of each wanted topic; a missing topic or an unexpected type is named."""
    by_topic = {c.topic: c for c in reader.connections}
    wanted = {"image": IMAGE_TYPES, "scan": SCAN_TYPES, "cmd": CMD_TYPES, "odom": ODOM_TYPES}
    conns = {}
    for name, allowed in wanted.items():
        topic = getattr(topics, name)
        if name == "odom" and not topic:
            continue
        if topic not in by_topic:
            raise ConfigError(
                f"{bag}: no topic {topic} (--{name}-topic); the bag has "
                f"{', '.join(sorted(by_topic)) or 'no topics'}"
            )
        conn = by_topic[topic]
        if conn.msgtype not in allowed:
            raise DataError(
                f"{bag}: topic {topic} has message type {conn.msgtype}, expected {' or '.join(allowed)}"
            )
        conns[name] = conn
    return conns


def _messages(bag: Path, reader: Reader, conn: Any) -> Iterator[tuple[int, Any]]:
    """(log time, message) of one connection; a cut-off or garbled file is a DataError naming it."""
    try:
        for _, log_ns, raw in reader.messages(connections=[conn]):
            yield log_ns, TYPESTORE.deserialize_cdr(raw, conn.msgtype)
    except (ReaderError, OSError, ValueError, KeyError, IndexError, struct.error) as err:
        raise DataError(f"{bag}: cannot read topic {conn.topic} (truncated or corrupted? {err})") from err


def _monotonic(bag: Path, topic: str, ns: list[int]) -> np.ndarray:
    stamps = np.asarray(ns, dtype=np.int64)
    bad = np.flatnonzero(np.diff(stamps) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise DataError(
            f"{bag}: stamps on {topic} are not increasing: message {i} at {stamps[i]} ns "
            f"follows {stamps[i - 1]} ns"
        )
    return stamps


def _read_streams(bag: Path, reader: Reader, conns: dict[str, Any]) -> _Streams:
    frame_ns = [_stamp_ns(m.header) for _, m in _messages(bag, reader, conns["image"])]
    scan_ns, scans = [], []
    for _, m in _messages(bag, reader, conns["scan"]):
        scan_ns.append(_stamp_ns(m.header))
        scans.append(_scan_to_rays(m))
    cmd_ns, cmds = [], []
    for log_ns, m in _messages(bag, reader, conns["cmd"]):
        twist = m.twist if hasattr(m, "twist") else m
        cmd_ns.append(_stamp_ns(m.header) if hasattr(m, "header") else log_ns)
        cmds.append((twist.linear.x, twist.angular.z))
    odom_ns, poses = [], []
    if "odom" in conns:
        for _, m in _messages(bag, reader, conns["odom"]):
            odom_ns.append(_stamp_ns(m.header))
            q = m.pose.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            poses.append((m.pose.pose.position.x, m.pose.pose.position.y, yaw))
    if poses:  # a continuous heading, as the simulator records it, rather than one wrapped to ±π
        poses = np.asarray(poses)
        poses[:, 2] = np.unwrap(poses[:, 2])
    topic = {name: conn.topic for name, conn in conns.items()}
    for name, stamps in (("image", frame_ns), ("scan", scan_ns), ("cmd", cmd_ns)):
        if not stamps:
            raise DataError(f"{bag}: topic {topic[name]} has no messages")
    frames, commands = _monotonic(bag, topic["image"], frame_ns), _monotonic(bag, topic["cmd"], cmd_ns)
    cmds = np.asarray(cmds, np.float64)
    return _Streams(
        frame_ns=frames,
        scan_ns=_monotonic(bag, topic["scan"], scan_ns),
        scans=np.asarray(scans, np.float32),
        odom_ns=_monotonic(bag, topic.get("odom", ""), odom_ns),
        poses=np.asarray(poses, np.float32).reshape(-1, 3),
        frame_cmds=_frame_commands(frames, commands, cmds),
    )


def _scan_to_rays(msg: Any) -> np.ndarray:
    """A LaserScan → 360 readings at 0°, 1°, … counter-clockwise: the nearest ray of the scan for each
    bearing (0, invalid, where the scan does not reach); beyond range_max → inf, below range_min or
    NaN → 0, as the simulated LDS-01 reports them."""
    ranges = np.asarray(msg.ranges, np.float64)
    if ranges.size == 0 or not msg.angle_increment > 0:
        return np.zeros(N_RAYS, np.float32)
    full_turn = round(2 * math.pi / msg.angle_increment)
    offset = (np.deg2rad(np.arange(N_RAYS)) - msg.angle_min) % (2 * math.pi)
    k = np.round(offset / msg.angle_increment).astype(np.int64)
    k = np.where(k >= full_turn, k - full_turn, k)  # just below angle_min: the first ray again
    r = np.where(k < ranges.size, ranges[np.minimum(k, ranges.size - 1)], 0.0)
    r = np.where(np.isnan(r) | (r < msg.range_min), 0.0, r)
    return np.where(r > msg.range_max, np.inf, r).astype(np.float32)


def _nearest(stamps: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the stamp nearest to each of `at`, and its distance in ns."""
    right = np.clip(np.searchsorted(stamps, at), 1, len(stamps) - 1) if len(stamps) > 1 else np.zeros_like(at)
    left = np.maximum(right - 1, 0)
    pick = np.where(np.abs(stamps[left] - at) <= np.abs(stamps[right] - at), left, right)
    return pick, np.abs(stamps[pick] - at)


def _frame_commands(frame_ns: np.ndarray, cmd_ns: np.ndarray, cmds: np.ndarray) -> np.ndarray:
    """Per frame, (linear, angular) of the last command sent before the next frame (NaN before the
    first command)."""
    until = np.append(frame_ns[1:], np.iinfo(np.int64).max)
    last = np.searchsorted(cmd_ns, until, side="left") - 1
    return np.where((last >= 0)[:, None], cmds[np.maximum(last, 0)], np.nan)


def _cut_runs(s: _Streams, max_gap_s: float) -> list[tuple[int, int]]:
    """(first, last) frame of each run: frames with a scan, the robot driving, no gap (module docstring)."""
    gap_ns = max_gap_s * 1e9
    _, scan_offset = _nearest(s.scan_ns, s.frame_ns)
    has_scan = scan_offset <= gap_ns / 2
    moving = np.abs(np.nan_to_num(s.frame_cmds[:, 0])) > STOPPED
    joined = np.append(np.diff(s.frame_ns) <= gap_ns, False)  # frame i and i + 1 belong together
    cuts, i, n = [], 0, len(s.frame_ns)
    while i < n:
        if not (has_scan[i] and moving[i]):
            i += 1
            continue
        j = i
        while moving[j] and joined[j] and has_scan[j + 1]:
            j += 1
        if j > i:
            cuts.append((i, j))
        i = j + 1
    return cuts


def _runs_with_images(
    bag: Path, reader: Reader, conns: dict[str, Any], cuts: list[tuple[int, int]]
) -> Iterator[tuple[int, int, np.ndarray]]:
    """Second pass over the images, yielding each run's decoded frames as soon as it is complete."""
    cut, frames = 0, []
    shape = None
    for t, (_, msg) in enumerate(_messages(bag, reader, conns["image"])):
        if cut == len(cuts):
            return
        first, last = cuts[cut]
        if t < first:
            continue
        image = _decode(bag, conns["image"].topic, t, msg)
        if shape is not None and image.shape != shape:
            raise DataError(
                f"{bag}: frame {t} on {conns['image'].topic} is {image.shape}, earlier ones {shape}"
            )
        shape = image.shape
        frames.append(image)
        if t == last:
            yield first, last, np.stack(frames)
            cut, frames = cut + 1, []


def _decode(bag: Path, topic: str, t: int, msg: Any) -> np.ndarray:
    if msg.__msgtype__ == "sensor_msgs/msg/Image":
        channels = {"rgb8": slice(None), "bgr8": slice(None, None, -1)}
        if msg.encoding not in channels:
            raise DataError(
                f"{bag}: frame {t} on {topic} has encoding {msg.encoding!r}, expected rgb8 or bgr8"
            )
        rows = np.asarray(msg.data, np.uint8).reshape(msg.height, msg.step)[:, : msg.width * 3]
        return np.ascontiguousarray(rows.reshape(msg.height, msg.width, 3)[..., channels[msg.encoding]])
    try:
        with Image.open(io.BytesIO(np.asarray(msg.data, np.uint8).tobytes())) as image:
            return np.array(image.convert("RGB"), dtype=np.uint8)
    except (UnidentifiedImageError, OSError) as err:
        raise DataError(f"{bag}: frame {t} on {topic} is not a readable image ({err})") from err


def _make_run(
    s: _Streams, first: int, last: int, images: np.ndarray, split: str, index: int, position: int
) -> Run:
    frames = np.arange(first, last + 1)
    scan_idx, _ = _nearest(s.scan_ns, s.frame_ns[frames])
    scans = s.scans[scan_idx]
    actions = s.frame_cmds[frames, 1].astype(np.float32)
    actions[-1] = np.nan
    if len(s.odom_ns):
        poses = s.poses[_nearest(s.odom_ns, s.frame_ns[frames])[0]]
    else:
        poses = np.full((len(frames), 3), np.nan, np.float32)
    meta = RunMeta(
        split=split,
        index=index,
        canyon_split="recorded",
        canyon_index=position,
        canyon_seed=0,
        policy_seed=0,
        end_reason="stop",
        n_frames=len(frames),
    )
    return Run(
        meta=meta,
        images=images,
        scans=scans,
        bins=depth_bins(scans, BinConfig()),
        actions=actions,
        poses=poses,
        times=((s.frame_ns[frames] - s.frame_ns[first]) / 1e9).astype(np.float32),
    )
