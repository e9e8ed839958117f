"""What a robot's node does, free of ROS: keep the newest camera frame, decide on it at the policy's
own rate, stop the robot when frames stop. `RobotDriver` is the one core that both thin nodes call,
`depthq ros drive` (ROS 1, `depthq.deploy.ros_drive`) and `examples/turtlebot3_ros2.py` (ROS 2);
docs/robot.md#ros-drive says how it behaves.
"""

from __future__ import annotations

import io
import math
import statistics
import threading
from dataclasses import dataclass, field

import numpy as np
from PIL import Image, UnidentifiedImageError

from depthq.control.policy import Policy
from depthq.deploy.resize import resize_frame
from depthq.errors import ConfigError, DataError

LINEAR_SPEED = 0.5  # m/s, the paper's constant forward speed
RAW_ENCODINGS = ("rgb8", "bgr8", "mono8")  # the `sensor_msgs/Image` encodings a camera driver gives
WATCHDOG_MARGIN = 3.0  # check periods before the watchdog's deadline at which the zero twist may leave


@dataclass(frozen=True)
class Twist:
    """A `geometry_msgs/Twist` in the two fields a TurtleBot3 uses: m/s forward, rad/s yaw (+left)."""

    linear_x: float
    angular_z: float


STOP = Twist(0.0, 0.0)


@dataclass(frozen=True)
class Frame:
    """One camera message as a node received it: a `sensor_msgs/CompressedImage` (`encoding` None:
    JPEG or PNG `data`) or a `sensor_msgs/Image` (`encoding` one of RAW_ENCODINGS, rows of `step`
    bytes). `stamp`: its header's time, s, on the clock the node runs on."""

    stamp: float
    data: bytes
    encoding: str | None = None
    height: int = 0
    width: int = 0
    step: int = 0


def decode_frame(data: bytes) -> np.ndarray:
    """A `sensor_msgs/CompressedImage` payload (JPEG or PNG) → uint8 RGB (H, W, 3)."""
    try:
        with Image.open(io.BytesIO(data)) as image:
            return np.array(image.convert("RGB"), dtype=np.uint8)  # a writable copy, as torch wants
    except (UnidentifiedImageError, OSError) as err:
        raise DataError(f"camera frame: not a JPEG or PNG image ({len(data)} bytes: {err})") from err


def decode_raw(data: bytes, encoding: str, height: int, width: int, step: int) -> np.ndarray:
    """A `sensor_msgs/Image` (rgb8, bgr8 or mono8; rows `step` bytes apart) → uint8 RGB (H, W, 3)."""
    if encoding not in RAW_ENCODINGS:
        raise DataError(f"camera frame: encoding {encoding!r} is not one of {RAW_ENCODINGS}")
    channels = 1 if encoding == "mono8" else 3
    if height < 1 or width < 1 or step < width * channels or len(data) < step * height:
        raise DataError(
            f"camera frame: {len(data)} bytes do not hold a {encoding} image of {height}×{width}, step {step}"
        )
    rows = np.frombuffer(data, np.uint8, count=step * height).reshape(height, step)
    pixels = rows[:, : width * channels].reshape(height, width, channels)
    if encoding == "mono8":
        return np.repeat(pixels, 3, axis=2)
    return np.ascontiguousarray(pixels[..., ::-1] if encoding == "bgr8" else pixels)


def decode(frame: Frame) -> np.ndarray:
    """A received camera message's image, uint8 RGB (H, W, 3)."""
    if frame.encoding is None:
        return decode_frame(frame.data)
    return decode_raw(frame.data, frame.encoding, frame.height, frame.width, frame.step)


def fit(image: np.ndarray, frame_size: tuple[int, int] | None) -> np.ndarray:
    """`image` at the frame size a policy's graph takes (None: any size, as a checkpoint's), resized as
    the graph and `depthq.nets.trunk.preprocess` resize (`depthq.deploy.resize`). Two resizes are not
    one: for a graph that sees the camera's frames as the checkpoint does, export it at the camera's
    size (`depthq export --frame-size HxW`)."""
    if frame_size is None or image.shape[:2] == tuple(frame_size):
        return image
    return resize_frame(image, frame_size)


def robot_policy(
    spec: str, weights: str | None = None, device: str = "cpu", hz: float | None = None
) -> tuple[Policy, float, tuple[int, int] | None]:
    """A learned policy for a robot, 'onnx:PATH' or a checkpoint folder: (the policy, the decision rate
    it was trained at (`hz` if given), the frame size its graph takes, None for a checkpoint's: any)."""
    from depthq.policies.spec import PolicySpec

    parsed = PolicySpec.parse(spec)
    if parsed.kind == "onnx":
        from depthq.policies.onnx import OnnxPolicy  # onnxruntime and numpy only, as on a robot

        policy = OnnxPolicy(parsed.path)
        rate = hz or policy.decision_hz
        if rate is None:
            raise ConfigError(f"{parsed.path}: records no decision rate (an older export); give --hz")
        return policy, rate, policy.frame_size
    if parsed.checkpoint is None:
        raise ConfigError(f"a robot drives a learned policy, a checkpoint folder or onnx:PATH; got {spec!r}")
    from depthq.nets.checkpoint import policy_record, read_config
    from depthq.policies.qnet import QNetPolicy

    policy = QNetPolicy.from_checkpoint(parsed.checkpoint, weights=weights, device=device)
    return policy, hz or policy_record(read_config(parsed.checkpoint)).decision_hz, None


def twist_for_frame(policy: Policy, frame: np.ndarray) -> Twist:
    """One decision: drive forward at LINEAR_SPEED, steer as the policy says on `frame`."""
    return Twist(LINEAR_SPEED, float(policy.act({"image": frame})))


@dataclass(frozen=True)
class DriverConfig:
    """How the node drives. `decision_hz`: the policy's trained rate (its checkpoint or ONNX metadata).
    `watchdog_s`: the longest the robot drives on after the newest fresh frame was taken; `max_age_s`: a
    frame older than this (now − its stamp) on arrival or at a decision is not decided on; `check_hz`:
    how often the node looks. Stamps and the node's clock must agree (one machine, or NTP/chrony)."""

    decision_hz: float
    watchdog_s: float = 0.5
    max_age_s: float = 0.5
    check_hz: float = 50.0

    def __post_init__(self) -> None:
        if not self.decision_hz > 0:
            raise ConfigError(f"the decision rate must be > 0 Hz, got {self.decision_hz}")
        if not self.check_hz >= 2 * self.decision_hz:
            raise ConfigError(f"--check-hz must be at least twice the decision rate, got {self.check_hz}")
        if not self.watchdog_s > WATCHDOG_MARGIN / self.check_hz:
            raise ConfigError(f"--watchdog must be > {WATCHDOG_MARGIN:g} checks long, got {self.watchdog_s}")
        if not self.max_age_s > 0:
            raise ConfigError(f"--max-age must be > 0 s, got {self.max_age_s}")

    @property
    def period(self) -> float:
        return 1.0 / self.decision_hz


@dataclass(frozen=True)
class Command:
    """What to publish: `twist`, and why ("decision" on the frame stamped `stamp`, "watchdog", "stop")."""

    twist: Twist
    reason: str
    stamp: float | None = None


@dataclass
class DriverStats:
    """What the node logs: decisions, their latencies (frame stamp → command published, s), stops."""

    decisions: int = 0
    skipped: int = 0  # decision times without a new fresh frame (the last command held)
    stale: int = 0  # frames dropped as older than max_age_s
    watchdog_stops: int = 0
    latencies: list[float] = field(default_factory=list)
    first: float | None = None  # the clock's time at the first and last decision
    last: float | None = None

    @property
    def rate(self) -> float:
        """Decisions per second between the first and the last."""
        if self.first is None or self.last is None or self.last <= self.first:
            return math.nan
        return (self.decisions - 1) / (self.last - self.first)

    def line(self) -> str:
        lat = sorted(self.latencies) or [math.nan]
        return (
            f"{self.decisions} decisions at {self.rate:.2f} Hz, latency frame→command median "
            f"{1e3 * statistics.median(lat):.0f} ms (max {1e3 * lat[-1]:.0f} ms), {self.skipped} times no "
            f"new frame, {self.stale} stale frames, {self.watchdog_stops} watchdog stops"
        )


class RobotDriver:
    """The node's logic. The camera callback calls `on_frame` (any thread: it only keeps the newest
    frame, decoded later and only if decided on); a timer calls `tick(now)` at `config.check_hz`, which
    returns the command to publish, if any: a decision at every decision time (the policy's rate) on the
    newest fresh frame not yet decided on, or one zero twist once the newest fresh frame is `watchdog_s` old.
    `stop()` is the command on shutdown, after which no tick commands anything."""

    def __init__(
        self, policy: Policy, config: DriverConfig, frame_size: tuple[int, int] | None = None
    ) -> None:
        """`frame_size`: the frame an ONNX graph takes (`OnnxPolicy.frame_size`); None for a checkpoint."""
        self.policy, self.config, self.frame_size = policy, config, frame_size
        self.stats = DriverStats()
        self._lock = threading.Lock()
        self._newest: Frame | None = None
        self._decided: float | None = None  # the stamp of the last frame decided on
        self._next: float | None = None  # the next decision time
        self._stopped = True  # the last command was a zero twist (or none was sent)
        self._shut = False  # `stop` was called: nothing moves the robot again

    def on_frame(self, frame: Frame, now: float) -> None:
        """Keep `frame` if it is fresh (its stamp within max_age_s of `now`, the receipt time)."""
        if now - frame.stamp > self.config.max_age_s:
            self.stats.stale += 1
            return
        with self._lock:
            if self._newest is None or frame.stamp >= self._newest.stamp:
                self._newest = frame

    def tick(self, now: float) -> Command | None:
        """The command to publish at `now` (the node's clock, as the stamps), or None."""
        cfg = self.config
        with self._lock:
            if self._shut:
                return None
            frame = self._newest
        # Counted from the newest frame's stamp (when it was taken), the zero twist leaves between three
        # and two check periods before watchdog_s, whatever the tick's phase: it reaches the robot by
        # then, with time to spare for a late tick and the network.
        silent = frame is None or now - frame.stamp >= cfg.watchdog_s - WATCHDOG_MARGIN / cfg.check_hz
        due = self._next is None or now >= self._next
        if due:
            self._next = now + cfg.period if self._next is None or now - self._next > cfg.period else (
                self._next + cfg.period)
        if silent:
            if self._stopped:
                return None
            self.stats.watchdog_stops += 1
            self._stopped = True
            return Command(STOP, "watchdog")
        if not due:
            return None
        if frame.stamp == self._decided or now - frame.stamp > cfg.max_age_s:
            self.stats.skipped += 1
            return None
        self._decided = frame.stamp
        twist = twist_for_frame(self.policy, fit(decode(frame), self.frame_size))
        self._stopped = False
        return Command(twist, "decision", frame.stamp)

    def published(self, command: Command, now: float) -> None:
        """Count a published decision and its latency (`now`: after publishing, the node's clock)."""
        if command.stamp is None:
            return
        self.stats.decisions += 1
        self.stats.latencies.append(now - command.stamp)
        self.stats.first = now if self.stats.first is None else self.stats.first
        self.stats.last = now

    def stop(self) -> Command:
        """The zero twist to publish on shutdown; every later `tick` returns None."""
        with self._lock:
            self._stopped = self._shut = True
        return Command(STOP, "stop")
