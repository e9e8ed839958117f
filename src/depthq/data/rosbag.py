"""ROS bags in and out of a dataset, read and written by `rosbags` (no ROS installation needed):
ROS 2 bags (a rosbag2 folder, MCAP or SQLite3) and ROS 1 bags (one `.bag` file, ROS 1 Noetic messages).

Export: every run of a dataset, one after the other, as the topics a TurtleBot3 publishes (the same
topics and contents in every format; a ROS 1 header's `seq` is 0):

    /camera/image_raw/compressed  sensor_msgs/CompressedImage  the run's JPEG frames, unchanged
    /scan                         sensor_msgs/LaserScan        360 rays from 0° counter-clockwise, 1° apart
    /cmd_vel                      geometry_msgs/Twist          0.5 m/s and the action, at the frame's stamp;
                                                               zero at a run's last frame (the robot stops)
    /odom                         nav_msgs/Odometry            the pose (x, y, yaw) and the command

Stamps are `EPOCH_S` + the run's own times; runs are `RUN_GAP_S` apart. An imported run's times start
at 0 at its first frame, and its heading is unwrapped (continuous) over the whole recording.

Import: a robot's recording becomes runs; a `.bag` file is read as ROS 1, a folder holding a
metadata.yaml as rosbag2. Frame t is each image; its scan is the one nearest to its stamp; its
action is the yaw rate of the last command sent before frame t + 1 was taken (the command that moved
the robot between the two frames); its pose the odometry nearest to its stamp.
A run ends where the robot stands (linear speed 0), where frames are more than `max_gap_s` apart,
or where no scan lies within `max_gap_s` / 2 of a frame. Runs keep the dataset layout of
`depthq.data.manifest` with `canyon_split="recorded"` and `end_reason="stop"`; the last
`val_runs` runs form the `val` split. The dataset is written in a hidden sibling folder and renamed
into place when complete, so a bad bag leaves nothing behind.

Scans: a `sensor_msgs/LaserScan` of any geometry becomes depthq's 360 readings (index i = bearing
i° counter-clockwise from the front, `depthq.sim.sensors`). Beam j points at angle_min + j ·
angle_increment (counter-clockwise from the front; a negative increment runs clockwise; angle_max is
not needed). Each bearing takes the reading of the beam nearest to it if that beam lies within half
a beam spacing (of two equally near, the first in the scan); a bearing outside the scanner's field
of view reads 0 (invalid), as do NaN and readings below range_min (−inf included); readings beyond
range_max (+inf included) read inf (no return).

Camera-only recordings: with `Topics(scan="")` (`--scan-topic ''`) a recording without a LiDAR
imports too; its frames need no scan, and its runs hold scans of all inf and bins of all NaN (no
depth was measured). Coll-Q-Net's targets come from where runs end, so it trains on them as on any
recording; Depth-Q-Net's NaN targets add no loss.
"""

from __future__ import annotations

import functools
import io
import math
import os
import shutil
import struct
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import astuple, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, UnidentifiedImageError
from rosbags import rosbag1, rosbag2
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore

from depthq.configio import to_dict, umask
from depthq.data.manifest import Dataset
from depthq.data.run import Run, RunMeta
from depthq.data.runfile import JPEG_QUALITY
from depthq.errors import ConfigError, DataError
from depthq.progress import Bar
from depthq.sim.sensors import N_RAYS, BinConfig, LidarConfig, depth_bins

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)  # the TurtleBot3's distribution; these messages never changed
ROS1_TYPESTORE = get_typestore(Stores.ROS1_NOETIC)  # ROS 1's last distribution, for .bag files
STORAGES = {"mcap": rosbag2.StoragePlugin.MCAP, "sqlite3": rosbag2.StoragePlugin.SQLITE3}
FORMATS = (*STORAGES, "ros1")  # what `export_bag` writes; the first is the default
EPOCH_S = 1_600_000_000  # the exported bag's first stamp (2020-09-13): equal datasets, equal bags
RUN_GAP_S = 10.0  # silence between two exported runs: longer than any import's max_gap_s
STOPPED = 1e-3  # m/s: a command slower than this stands the robot still
SAME_BEAM = 1e-3  # beam spacings: two beams this close in distance to a bearing tie (float32 angles)
READ_ERRORS = (  # everything a cut-off or garbled bag makes rosbags raise
    rosbag1.ReaderError,
    rosbag2.ReaderError,
    SerdeError,
    OSError,
    ValueError,
    KeyError,
    IndexError,
    struct.error,
)


@dataclass(frozen=True)
class Topics:
    """Where the streams are; the defaults are the TurtleBot3's (`odom=""` imports without poses,
    `scan=""` without scans: a camera-only recording)."""

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


def header_msg(ns: int, frame_id: str, typestore: Any = TYPESTORE) -> Any:
    """A std_msgs/Header of `typestore`'s distribution (ROS 1's has a `seq`: 0)."""
    t = typestore.types
    stamp = t["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    seq = {"seq": 0} if typestore is ROS1_TYPESTORE else {}
    return t["std_msgs/msg/Header"](**seq, stamp=stamp, frame_id=frame_id)


def _vector(typestore: Any, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Any:
    return typestore.types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


# ----------------------------------------------------------------------------------------- export


def export_bag(data: Path, out: Path, bag_format: str = FORMATS[0], progress: bool = True) -> Path:
    """Write every run of the dataset `data` as the new bag `out` (see the module docstring): a rosbag2
    folder ("mcap", "sqlite3") or a ROS 1 file named *.bag ("ros1")."""
    if bag_format not in FORMATS:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {bag_format!r}")
    out = Path(out)
    if bag_format == "ros1" and out.suffix != ".bag":
        raise ConfigError(f"{out}: a ROS 1 bag is one file named *.bag (what `depthq bag import` reads)")
    if out.exists():
        raise ConfigError(f"{out}: exists; a bag is written to a new path")
    dataset = Dataset.open(Path(data))
    speed = float(dataset.config.get("env", {}).get("world", {}).get("speed", 0.5))
    lidar = LidarConfig()
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        if bag_format == "ros1":
            ts, writer = ROS1_TYPESTORE, rosbag1.Writer(staging / out.name)
            serialize = ts.serialize_ros1
        else:
            ts = TYPESTORE
            writer = rosbag2.Writer(staging / out.name, version=9, storage_plugin=STORAGES[bag_format])
            serialize = ts.serialize_cdr
        with writer:
            types = (
                "sensor_msgs/msg/CompressedImage",
                "sensor_msgs/msg/LaserScan",
                "geometry_msgs/msg/Twist",
                "nav_msgs/msg/Odometry",
            )
            conns = [
                writer.add_connection(topic, msgtype, typestore=ts)
                for topic, msgtype in zip(astuple(Topics()), types, strict=True)
            ]
            start_ns = EPOCH_S * 1_000_000_000
            for entry in Bar(dataset.entries(), desc="bag export", unit="run", disable=not progress):
                with dataset.reader(entry) as reader:
                    run = reader.run(images=False)
                    for t in range(run.n_frames):
                        ns = start_ns + round(float(run.times[t]) * 1e9)
                        action = 0.0 if t == run.n_frames - 1 else float(run.actions[t])
                        linear = 0.0 if t == run.n_frames - 1 else speed
                        msgs = (
                            image_msg(reader.jpeg(t), ns, ts),
                            scan_msg(run.scans[t], ns, lidar, ts),
                            twist_msg(linear, action, ts),
                            odom_msg(run.poses[t], linear, action, ns, ts),
                        )
                        for conn, msg in zip(conns, msgs, strict=True):
                            writer.write(conn, ns, serialize(msg, conn.msgtype))
                start_ns += round((float(run.times[-1]) + RUN_GAP_S) * 1e9)
        os.replace(staging / out.name, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out


def image_msg(jpeg: bytes, ns: int, typestore: Any = TYPESTORE) -> Any:
    return typestore.types["sensor_msgs/msg/CompressedImage"](
        header=header_msg(ns, "camera_rgb_optical_frame", typestore),
        format="jpeg",
        data=np.frombuffer(jpeg, np.uint8),
    )


def scan_msg(scan: np.ndarray, ns: int, lidar: LidarConfig, typestore: Any = TYPESTORE) -> Any:
    step = 2 * math.pi / N_RAYS
    return typestore.types["sensor_msgs/msg/LaserScan"](
        header=header_msg(ns, "base_scan", typestore),
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


def twist_msg(linear: float, angular: float, typestore: Any = TYPESTORE) -> Any:
    return typestore.types["geometry_msgs/msg/Twist"](
        linear=_vector(typestore, x=linear), angular=_vector(typestore, z=angular)
    )


def odom_msg(pose: np.ndarray, linear: float, angular: float, ns: int, typestore: Any = TYPESTORE) -> Any:
    t = typestore.types
    x, y, yaw = (float(v) for v in pose)
    orientation = t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    pose_msg = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=orientation
    )
    return t["nav_msgs/msg/Odometry"](
        header=header_msg(ns, "odom", typestore),
        child_frame_id="base_footprint",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose_msg, covariance=np.zeros(36)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=twist_msg(linear, angular, typestore), covariance=np.zeros(36)
        ),
    )


# ----------------------------------------------------------------------------------------- import


@dataclass(frozen=True)
class ImportConfig:
    """How a recording is cut into runs; stored as the imported dataset's config."""

    topics: Topics = Topics()
    max_gap_s: float = 1.0
    # The last N runs form the val split, at least one run left to train on (more is refused); none:
    # 1, or 0 for a recording of one run. The dataset's config records the number taken.
    val_runs: int | None = None
    jpeg_quality: int = JPEG_QUALITY

    def __post_init__(self) -> None:
        if not 0 < self.max_gap_s < math.inf:
            raise ConfigError(f"--max-gap must be a number of seconds > 0, got {self.max_gap_s}")
        if self.val_runs is not None and self.val_runs < 0:
            raise ConfigError(f"--val-runs must be >= 0, got {self.val_runs}")
        for name in ("image", "scan", "cmd"):
            topic = getattr(self.topics, name)
            if not topic.startswith("/") and not (name == "scan" and topic == ""):
                hint = " (or '' for a recording without scans)" if name == "scan" else ""
                raise ConfigError(
                    f"--{name}-topic must be a ROS topic name starting with '/'{hint}, got {topic!r}"
                )


@dataclass(frozen=True)
class _Bag:
    """An open recording: its path, its reader, and how its messages decode."""

    path: Path
    reader: Any  # a rosbags rosbag1 or rosbag2 Reader: both list .connections and yield .messages()
    deserialize: Callable[[bytes, str], Any]  # raw bytes, message type → message
    source: str  # "rosbag1" or "rosbag2", as the imported dataset's config records it


@dataclass(frozen=True)
class _Streams:
    """Everything but the images, read in a first pass: stamps in ns, sorted as recorded."""

    frame_ns: np.ndarray  # (F,) image stamps
    scan_ns: np.ndarray  # (S,); empty without a scan topic
    scans: np.ndarray  # (S, 360) float32 in depthq's convention (0 invalid, inf no return)
    odom_ns: np.ndarray  # (O,); empty without an odometry topic
    poses: np.ndarray  # (O, 3)
    frame_cmds: np.ndarray  # (F, 2) linear x, angular z of the command in force after each frame


def import_bag(bag: Path, out: Path, config: ImportConfig = ImportConfig(), progress: bool = True) -> Dataset:
    """Turn the recording `bag` (a ROS 1 .bag file or a rosbag2 folder) into a new dataset folder `out`
    (see the module docstring)."""
    bag, out = Path(bag), Path(out)
    if out.exists():
        raise ConfigError(f"{out}: exists; a bag is imported into a new folder")
    if not bag.exists():
        raise ConfigError(f"{bag}: no such bag")
    with _open(bag) as rec:
        conns = _connections(rec, config.topics)
        streams = _read_streams(rec, conns)
        cuts = _cut_runs(streams, config.max_gap_s)
        if not cuts:
            scan = f", with a scan within {config.max_gap_s / 2:g} s" if "scan" in conns else ""
            raise ConfigError(f"{bag}: no run found (no frame while the robot drove{scan}); nothing written")
        if config.val_runs is None:
            config = replace(config, val_runs=min(1, len(cuts) - 1))
        elif config.val_runs > len(cuts) - 1:
            raise ConfigError(f"--val-runs {config.val_runs}: {bag} holds {len(cuts)} run(s), and at least "
                              f"one must train: give at most {len(cuts) - 1}; nothing written")
        out.parent.mkdir(parents=True, exist_ok=True)
        for stale in out.parent.glob(f".{out.name}.*.tmp"):  # a killed import's (its --out is locked)
            shutil.rmtree(stale, ignore_errors=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
        staging.chmod(0o777 & ~umask())  # the dataset's folder: as `mkdir` would make it, not mkdtemp's 0o700
        try:
            record = {"source": rec.source, "bag": bag.name, **to_dict(config)}
            dataset = Dataset.create(staging, record, seed=0)
            n_val = int(config.val_runs)
            bar = Bar(total=len(cuts), desc="bag import", unit="run", disable=not progress)
            for position, (first, last, images) in enumerate(_runs_with_images(rec, conns, cuts)):
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
def _open(bag: Path) -> Iterator[_Bag]:
    """The recording read by the reader its path asks for (a .bag file: ROS 1; a folder with a
    metadata.yaml: rosbag2), every way it can be unreadable turned into a DataError naming it."""
    if bag.is_file() and bag.suffix == ".bag":
        source, make, deserialize = "rosbag1", rosbag1.Reader, ROS1_TYPESTORE.deserialize_ros1
    elif (bag / "metadata.yaml").is_file():
        source, make, deserialize = "rosbag2", rosbag2.Reader, TYPESTORE.deserialize_cdr
    else:
        raise ConfigError(
            f"{bag}: neither a ROS 1 bag (a file named *.bag) nor a rosbag2 bag (a folder with a "
            "metadata.yaml)"
        )
    try:
        reader = make(bag)
        reader.open()
    except READ_ERRORS as err:
        raise DataError(f"{bag}: not a readable {source} bag ({err})") from err
    try:
        yield _Bag(bag, reader, deserialize, source)
    finally:
        reader.close()


def _connections(rec: _Bag, topics: Topics) -> dict[str, list[Any]]:
    """The connections of each wanted topic (ROS 1 has one per publishing node); a missing topic or an
    unexpected type is named."""
    by_topic: dict[str, list[Any]] = {}
    for conn in rec.reader.connections:
        by_topic.setdefault(conn.topic, []).append(conn)
    wanted = {"image": IMAGE_TYPES, "scan": SCAN_TYPES, "cmd": CMD_TYPES, "odom": ODOM_TYPES}
    conns = {}
    for name, allowed in wanted.items():
        topic = getattr(topics, name)
        if name in ("scan", "odom") and not topic:
            continue
        if topic not in by_topic:
            raise ConfigError(
                f"{rec.path}: no topic {topic} (--{name}-topic); the bag has "
                f"{', '.join(sorted(by_topic)) or 'no topics'}"
            )
        for conn in by_topic[topic]:
            if conn.msgtype not in allowed:
                raise DataError(
                    f"{rec.path}: topic {topic} has message type {conn.msgtype}, "
                    f"expected {' or '.join(allowed)}"
                )
        conns[name] = by_topic[topic]
    return conns


def _messages(rec: _Bag, conns: list[Any]) -> Iterator[tuple[int, Any]]:
    """(log time, message) of one topic's connections in log order; a cut-off or garbled file is a
    DataError naming it."""
    try:
        for conn, log_ns, raw in rec.reader.messages(connections=conns):
            yield log_ns, rec.deserialize(raw, conn.msgtype)
    except READ_ERRORS as err:
        raise DataError(
            f"{rec.path}: cannot read topic {conns[0].topic} (truncated or corrupted? {err})"
        ) from err


def _monotonic(bag: Path, topic: str, ns: list[int], ties: bool = False) -> np.ndarray:
    """The stamps, checked to increase; `ties`: equal stamps allowed (log times of messages received
    within one tick of a simulated /clock), the later message then the one in force."""
    stamps = np.asarray(ns, dtype=np.int64)
    bad = np.flatnonzero(np.diff(stamps) < 0 if ties else np.diff(stamps) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise DataError(
            f"{bag}: stamps on {topic} are not increasing: message {i} at {stamps[i]} ns "
            f"follows {stamps[i - 1]} ns"
        )
    return stamps


def _read_streams(rec: _Bag, conns: dict[str, list[Any]]) -> _Streams:
    frame_ns = [_stamp_ns(m.header) for _, m in _messages(rec, conns["image"])]
    scan_ns, scans = [], []
    if "scan" in conns:
        for _, m in _messages(rec, conns["scan"]):
            scan_ns.append(_stamp_ns(m.header))
            scans.append(_scan_to_rays(m))
    cmd_ns, cmds, logged = [], [], False
    for log_ns, m in _messages(rec, conns["cmd"]):
        twist = m.twist if hasattr(m, "twist") else m
        cmd_ns.append(_stamp_ns(m.header) if hasattr(m, "header") else log_ns)
        logged = logged or not hasattr(m, "header")  # a Twist's stamp: when the recorder logged it
        cmds.append((twist.linear.x, twist.angular.z))
    odom_ns, poses = [], []
    if "odom" in conns:
        for _, m in _messages(rec, conns["odom"]):
            odom_ns.append(_stamp_ns(m.header))
            q = m.pose.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            poses.append((m.pose.pose.position.x, m.pose.pose.position.y, yaw))
    if poses:  # a continuous heading, as the simulator records it, rather than one wrapped to ±π
        poses = np.asarray(poses)
        poses[:, 2] = np.unwrap(poses[:, 2])
    topic = {name: connections[0].topic for name, connections in conns.items()}
    for name, stamps in (("image", frame_ns), ("scan", scan_ns), ("cmd", cmd_ns)):
        if name in conns and not stamps:
            raise DataError(f"{rec.path}: topic {topic[name]} has no messages")
    frames = _monotonic(rec.path, topic["image"], frame_ns)
    commands = _monotonic(rec.path, topic["cmd"], cmd_ns, ties=logged)
    cmds = np.asarray(cmds, np.float64)
    return _Streams(
        frame_ns=frames,
        scan_ns=_monotonic(rec.path, topic.get("scan", ""), scan_ns),
        scans=np.asarray(scans, np.float32).reshape(-1, N_RAYS),
        odom_ns=_monotonic(rec.path, topic.get("odom", ""), odom_ns),
        poses=np.asarray(poses, np.float32).reshape(-1, 3),
        frame_cmds=_frame_commands(frames, commands, cmds),
    )


def _scan_to_rays(msg: Any) -> np.ndarray:
    """A LaserScan of any geometry → 360 readings at 0°, 1°, … counter-clockwise, by the module
    docstring's rule: each bearing's nearest beam within half a beam spacing (0, invalid, where there is
    none); NaN or below range_min (−inf too) → 0; beyond range_max (+inf too) → inf, as the simulated
    LDS-01 reports them."""
    ranges = np.asarray(msg.ranges, np.float64)
    beam = _beam_of_bearing(float(msg.angle_min), float(msg.angle_increment), ranges.size)
    r = np.append(ranges, 0.0)[beam]  # no beam (−1): the appended 0, invalid
    r = np.where(np.isnan(r) | (r < msg.range_min), 0.0, r)
    return np.where(r > msg.range_max, np.inf, r).astype(np.float32)


@functools.lru_cache(maxsize=16)
def _beam_of_bearing(angle_min: float, increment: float, n_beams: int) -> np.ndarray:
    """For each bearing 0°, 1°, … 359°, the index of the beam nearest to it (the first of equally near
    ones), or −1 where no beam lies within half a beam spacing. A scanner's geometry rarely changes,
    so the answer is computed once for each; read-only, because it is shared."""
    spacing = abs(increment)
    if n_beams == 0 or not (math.isfinite(angle_min) and math.isfinite(spacing) and spacing > 0):
        beam = np.full(N_RAYS, -1, np.int64)  # no beams, or angles that point nowhere
    else:
        beams = angle_min + increment * np.arange(n_beams)
        angle = beams[None, :] - np.deg2rad(np.arange(N_RAYS))[:, None]  # beam − bearing, (360, n_beams)
        apart = np.abs((angle + math.pi) % (2 * math.pi) - math.pi) / spacing  # in beam spacings
        nearest = apart.min(axis=1, keepdims=True)
        first = np.argmax(apart <= nearest + SAME_BEAM, axis=1)
        beam = np.where(nearest[:, 0] <= 0.5 + SAME_BEAM, first, -1)
    beam.setflags(write=False)
    return beam


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
    """(first, last) frame of each run: frames with a scan (any frame without a scan topic), the robot
    driving, no gap (module docstring)."""
    gap_ns = max_gap_s * 1e9
    if len(s.scan_ns):
        has_scan = _nearest(s.scan_ns, s.frame_ns)[1] <= gap_ns / 2
    else:
        has_scan = np.ones(len(s.frame_ns), bool)
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
    rec: _Bag, conns: dict[str, list[Any]], cuts: list[tuple[int, int]]
) -> Iterator[tuple[int, int, np.ndarray]]:
    """Second pass over the images, yielding each run's decoded frames as soon as it is complete."""
    cut, frames = 0, []
    shape = None
    topic = conns["image"][0].topic
    for t, (_, msg) in enumerate(_messages(rec, conns["image"])):
        if cut == len(cuts):
            return
        first, last = cuts[cut]
        if t < first:
            continue
        image = _decode(rec.path, topic, t, msg)
        if shape is not None and image.shape != shape:
            raise DataError(f"{rec.path}: frame {t} on {topic} is {image.shape}, earlier ones {shape}")
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
    if len(s.scan_ns):
        scans = s.scans[_nearest(s.scan_ns, s.frame_ns[frames])[0]]
        bins = depth_bins(scans, BinConfig())
    else:  # a camera-only recording: nothing measured
        scans = np.full((len(frames), N_RAYS), np.inf, np.float32)
        bins = np.full((len(frames), BinConfig().n_bins), np.nan, np.float32)
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
        bins=bins,
        actions=actions,
        poses=poses,
        times=((s.frame_ns[frames] - s.frame_ns[first]) / 1e9).astype(np.float32),
    )
