"""What a robot's node does, free of ROS: keep the newest camera frame that decodes, decide on it at the
policy's own rate, stop the robot when usable frames stop, decisions stall or the clock jumps back.
`RobotDriver` is the one core that both thin nodes call, `depthq ros drive` (ROS 1,
`depthq.deploy.ros_drive`) and `examples/turtlebot3_ros2.py` (ROS 2); docs/robot.md#ros-drive says
how it behaves.
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
from depthq.policies.spec import PolicySpec

LINEAR_SPEED = 0.5  # m/s, the paper's constant forward speed
RAW_ENCODINGS = ("rgb8", "bgr8", "mono8")  # the `sensor_msgs/Image` encodings a camera driver gives
WATCHDOG_MARGIN = 3.0  # check periods before the watchdog's deadline at which the zero twist may leave
MAX_PIXELS = 4096 * 3072  # a larger frame is refused unread: its decoding alone would outlast a decision
CLOCK_JUMP_S = 1e-3  # the node's clock running back by more than this: a restarted simulator or bag


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


def decode_frame(data: bytes, max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """A `sensor_msgs/CompressedImage` payload (JPEG or PNG) → uint8 RGB (H, W, 3); an image of more than
    `max_pixels` is refused from its header, before it is decoded."""
    try:
        with Image.open(io.BytesIO(data)) as image:
            width, height = image.size
            if width * height > max_pixels:
                raise DataError(f"camera frame: {width}×{height} is more than {max_pixels} pixels")
            return np.array(image.convert("RGB"), dtype=np.uint8)  # a writable copy, as torch wants
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError) as err:
        raise DataError(f"camera frame: not a JPEG or PNG image ({len(data)} bytes: {err})") from err


def decode_raw(
    data: bytes, encoding: str, height: int, width: int, step: int, max_pixels: int = MAX_PIXELS
) -> np.ndarray:
    """A `sensor_msgs/Image` (rgb8, bgr8 or mono8; rows `step` bytes apart) → uint8 RGB (H, W, 3)."""
    if encoding not in RAW_ENCODINGS:
        raise DataError(f"camera frame: encoding {encoding!r} is not one of {RAW_ENCODINGS}")
    if height * width > max_pixels:
        raise DataError(f"camera frame: {width}×{height} is more than {max_pixels} pixels")
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


def decode(frame: Frame, max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """A received camera message's image, uint8 RGB (H, W, 3)."""
    if frame.encoding is None:
        return decode_frame(frame.data, max_pixels)
    return decode_raw(frame.data, frame.encoding, frame.height, frame.width, frame.step, max_pixels)


def fit(image: np.ndarray, frame_size: tuple[int, int] | None) -> np.ndarray:
    """`image` at the frame size a policy's graph takes (None: any size, as a checkpoint's), resized as
    the graph and `depthq.blocks.trunk.preprocess` resize (`depthq.deploy.resize`). Two resizes are not
    one: for a graph that sees the camera's frames as the checkpoint does, export it at the camera's
    size (`depthq export --frame-size HxW`)."""
    if frame_size is None or image.shape[:2] == tuple(frame_size):
        return image
    return resize_frame(image, frame_size)


def robot_policy(
    spec: PolicySpec, weights: str | None = None, device: str = "cpu", hz: float | None = None
) -> tuple[Policy, float, tuple[int, int] | None]:
    """A learned policy for a robot, 'onnx:PATH' or a checkpoint folder: (the policy, the decision rate
    it was trained at (`hz` if given), the frame size its graph takes, None for a checkpoint's: any)."""
    if spec.kind == "onnx":
        from depthq.policies.onnx import OnnxPolicy  # onnxruntime and numpy only, as on a robot

        policy = OnnxPolicy(spec.path)
        rate = hz or policy.decision_hz
        if rate is None:
            raise ConfigError(f"{spec.path}: records no decision rate (an older export); give --hz")
        return policy, rate, policy.frame_size
    if spec.checkpoint is None:
        raise ConfigError(
            f"a robot drives a learned policy, a checkpoint folder or onnx:PATH; got {spec.name!r}"
        )
    from depthq.checkpoint import policy_record, read_config
    from depthq.policies.qnet import QNetPolicy

    policy = QNetPolicy.from_checkpoint(spec.checkpoint, weights=weights, device=device)
    return policy, hz or policy_record(read_config(spec.checkpoint)).decision_hz, None


def twist_for_frame(policy: Policy, frame: np.ndarray) -> Twist:
    """One decision: drive forward at LINEAR_SPEED, steer as the policy says on `frame`."""
    return Twist(LINEAR_SPEED, float(policy.act({"image": frame})))


@dataclass(frozen=True)
class DriverConfig:
    """How the node drives. `decision_hz`: the policy's trained rate (its checkpoint or ONNX metadata).
    `watchdog_s`: the longest the robot drives on after the newest usable frame was taken; `max_age_s`: a
    frame stamped more than this before (stale) or after (from another clock) the node's clock on
    arrival, or older at a decision, is not decided on; `check_hz`: how often the node looks;
    `max_pixels`: a larger frame is refused before it is decoded. Stamps and the node's clock must
    agree (one machine, or NTP/chrony)."""

    decision_hz: float
    watchdog_s: float = 0.5
    max_age_s: float = 0.5
    check_hz: float = 50.0
    max_pixels: int = MAX_PIXELS

    def __post_init__(self) -> None:
        if not self.decision_hz > 0:
            raise ConfigError(f"the decision rate must be > 0 Hz, got {self.decision_hz}")
        if not self.check_hz >= 2 * self.decision_hz:
            raise ConfigError(f"--check-hz must be at least twice the decision rate, got {self.check_hz}")
        if not self.watchdog_s > WATCHDOG_MARGIN / self.check_hz:
            raise ConfigError(f"--watchdog must be > {WATCHDOG_MARGIN:g} checks long, got {self.watchdog_s}")
        if not self.max_age_s > 0:
            raise ConfigError(f"--max-age must be > 0 s, got {self.max_age_s}")
        if not self.max_pixels >= 1:
            raise ConfigError(f"--max-pixels must be ≥ 1, got {self.max_pixels}")

    @property
    def period(self) -> float:
        return 1.0 / self.decision_hz

    @property
    def silent_after(self) -> float:
        """Seconds after the newest usable frame's stamp at which the watchdog's zero twist leaves:
        between three and two check periods before `watchdog_s`, whatever the check's phase, so that
        it reaches the robot by then, with time to spare for a late check and the network."""
        return self.watchdog_s - WATCHDOG_MARGIN / self.check_hz


@dataclass(frozen=True)
class Command:
    """What to publish: `twist`, and why ("decision" on the frame stamped `stamp`; a zero twist's
    reason: "watchdog", "clock jumped back", "decisions stalled", "decision failed", "stop")."""

    twist: Twist
    reason: str
    stamp: float | None = None


@dataclass(frozen=True)
class Usable:
    """A frame that decoded: its stamp and its image, at the size the policy takes."""

    stamp: float
    image: np.ndarray


@dataclass
class DriverStats:
    """What the node logs: decisions, their latencies (frame stamp → command published, s), frames
    dropped and why, stops."""

    decisions: int = 0
    skipped: int = 0  # decision times without a new fresh frame (the last command held)
    stale: int = 0  # frames stamped more than max_age_s before the node's clock
    future: int = 0  # frames stamped more than max_age_s after it: another clock
    bad: int = 0  # frames that did not decode (empty, corrupt, an unknown encoding, 0 or too many pixels)
    failed: int = 0  # decisions whose policy raised
    watchdog_stops: int = 0
    clock_jumps: int = 0
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
            f"new frame, {self.stale} stale frames, {self.future} from another clock, {self.bad} bad frames, "
            f"{self.failed} failed decisions, {self.watchdog_stops} watchdog stops, {self.clock_jumps} "
            "clock jumps"
        )


class RobotDriver:
    """The node's logic, safe whatever arrives. The camera callback calls `on_frame` (any thread): it
    decodes the frame there, off the loops, and keeps the newest that decodes and is fresh. Two loops
    call the rest, each at `config.check_hz`: `watch(now)`, the watchdog, returns one zero twist when the
    newest usable frame is `watchdog_s` old, when decisions have stalled, or when the clock jumped back
    (a restarted simulator, a looped bag: everything from the old clock is dropped); `decide(now)` runs
    the policy at each decision time (the policy's rate) on the newest fresh frame not yet decided on,
    and `commit(command, now)` lets the decision out only if nothing stopped the robot meanwhile.
    `tick(now)` is both loops in one (a single timer). `stop()` is the command on shutdown, after which
    nothing moves the robot again."""

    def __init__(
        self, policy: Policy, config: DriverConfig, frame_size: tuple[int, int] | None = None
    ) -> None:
        """`frame_size`: the frame an ONNX graph takes (`OnnxPolicy.frame_size`); None for a checkpoint."""
        self.policy, self.config, self.frame_size = policy, config, frame_size
        self.stats = DriverStats()
        self._lock = threading.Lock()
        self._newest: Usable | None = None
        self._decided: float | None = None  # the stamp of the last frame decided on
        self._moving_on: float | None = None  # the stamp of the frame the robot's last command came from
        self._next: float | None = None  # the next decision time
        self._clock: float | None = None  # the latest time `watch` saw
        self._epoch = 0  # counts clock jumps back: a decision taken before one is not let out
        self._stopped = True  # the last command was a zero twist (or none was sent)
        self._shut = False  # `stop` was called: nothing moves the robot again
        self.failure: str | None = None  # why the last failed decision failed

    def on_frame(self, frame: Frame, now: float) -> str | None:
        """Keep `frame` if it is fresh (stamped within max_age_s of `now`, the receipt time, either way)
        and decodes; else count it and return why it was dropped."""
        cfg = self.config
        if now - frame.stamp > cfg.max_age_s:
            self.stats.stale += 1
            return f"stale: stamped {now - frame.stamp:.2f} s before this node's clock"
        if frame.stamp - now > cfg.max_age_s:
            self.stats.future += 1
            return f"from another clock: stamped {frame.stamp - now:.2f} s after this node's clock"
        try:
            image = fit(decode(frame, cfg.max_pixels), self.frame_size)
        except Exception as err:  # anything a camera sends: the frame is dropped, never the node
            self.stats.bad += 1
            return f"bad frame: {err}"
        with self._lock:
            if self._newest is None or frame.stamp >= self._newest.stamp:
                self._newest = Usable(frame.stamp, image)
        return None

    def watch(self, now: float) -> Command | None:
        """The watchdog's check at `now` (the node's clock, as the stamps): a zero twist, or None."""
        cfg = self.config
        with self._lock:
            if self._shut:
                return None
            reason = None
            if self._clock is not None and now < self._clock - CLOCK_JUMP_S:
                self.stats.clock_jumps += 1
                self._newest = self._decided = self._moving_on = self._next = None
                self._epoch += 1
                reason = "clock jumped back"
            self._clock = now if reason is not None or self._clock is None else max(self._clock, now)
            newest = self._newest
            if reason is None and (newest is None or now - newest.stamp >= cfg.silent_after):
                reason = "watchdog"
            if reason is None and self._moving_on is not None and (
                    now - self._moving_on >= cfg.period + cfg.silent_after):
                reason = "decisions stalled"
            if reason is None or self._stopped:
                return None
            self.stats.watchdog_stops += 1
            self._stopped, self._moving_on = True, None
            return Command(STOP, reason)

    def decide(self, now: float) -> Command | None:
        """At a decision time, the policy's command on the newest fresh frame not yet decided on (to
        `commit` before publishing); a zero twist if the policy raised; else None."""
        cfg = self.config
        with self._lock:
            if self._shut:
                return None
            due = self._next is None or now >= self._next
            if not due:
                return None
            self._next = now + cfg.period if self._next is None or now - self._next > cfg.period else (
                self._next + cfg.period)
            frame = self._newest
            if frame is None or frame.stamp == self._decided or now - frame.stamp > cfg.max_age_s:
                self.stats.skipped += 1
                return None
            self._decided, epoch = frame.stamp, self._epoch
        try:
            twist = twist_for_frame(self.policy, frame.image)
        except Exception as err:  # a policy that fails once must not leave the robot on its last command
            self.stats.failed += 1
            self.failure = f"{type(err).__name__}: {err}"
            return Command(STOP, "decision failed")
        return Command(twist, "decision", frame.stamp) if epoch == self._epoch else None

    def commit(self, command: Command, now: float) -> bool:
        """Whether `command` (from `decide`) may be published at `now`: not after `stop`, not a decision
        on a frame the watchdog has given up on, not a second zero twist. Counts what it lets out."""
        with self._lock:
            if self._shut:
                return False
            if command.stamp is None:  # a failed decision's zero twist
                if self._stopped:
                    return False
                self._stopped, self._moving_on = True, None
                return True
            if not -self.config.max_age_s <= now - command.stamp < self.config.silent_after:
                return False  # given up on by the watchdog, or taken on a clock that has since jumped
            self._stopped, self._moving_on = False, command.stamp
            self.stats.decisions += 1
            self.stats.latencies.append(now - command.stamp)
            self.stats.first = now if self.stats.first is None else self.stats.first
            self.stats.last = now
            return True

    def tick(self, now: float) -> Command | None:
        """`watch`, then `decide` and `commit` at the same `now`: both loops in one timer."""
        stop = self.watch(now)
        if stop is not None:
            return stop
        command = self.decide(now)
        return command if command is not None and self.commit(command, now) else None

    def stop(self) -> Command:
        """The zero twist to publish on shutdown; every later check returns None."""
        with self._lock:
            self._stopped = self._shut = True
        return Command(STOP, "stop")
