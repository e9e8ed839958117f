"""`depthq ros drive`: a ROS 1 node around `depthq.deploy.robot.RobotDriver`, camera in, /cmd_vel out.

The camera topic's type follows image_transport's naming: a topic ending in `/compressed` carries
`sensor_msgs/CompressedImage` (JPEG or PNG), any other `sensor_msgs/Image` (rgb8, bgr8, mono8). The
subscription keeps one message (queue 1, a receive buffer larger than a frame, so that rospy never
delivers an old one) and decodes it in its own thread. Three loops of the node's own, each a thread
timed by the wall clock (rospy's timers end for good when the ROS clock runs back), read the ROS clock:
the watchdog, the decisions and a monitor (log lines, frames dropped, the master). None dies of an
exception: the decision loop logs it and goes on (the watchdog stops the robot if decisions stall);
a watchdog that fails publishes a zero twist and ends the node with an error, for a supervisor to
restart it. On shutdown (SIGINT, `rosnode kill`, the master gone) the node publishes a zero twist
before it leaves (docs/robot.md#ros-drive).
"""

from __future__ import annotations

import math
import socket
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import urlparse

from depthq.deploy.robot import Command, DriverConfig, Frame, RobotDriver, robot_policy
from depthq.deploy.ros1 import import_rospy, require_master
from depthq.policies.spec import PolicySpec

BUFFER_BYTES = 1 << 24  # rospy's receive buffer: larger than any frame, or it delivers stale ones
FORWARD_JUMP_S = 1.0  # the ROS clock running this much ahead of the wall clock between two checks
MASTER_CHECK_S = 1.0  # how often the monitor knocks at the master's port
MASTER_MISSES = 2  # knocks unanswered in a row: the master is gone
DROPS_EVERY_S = 1.0  # frames dropped: one log line at most this often


@dataclass(frozen=True)
class DriveNodeConfig:
    """The node's topics and logging; `driver` how it decides (`DriverConfig`)."""

    image_topic: str = "/camera/image_raw/compressed"
    cmd_topic: str = "/cmd_vel"
    node_name: str = "depthq_drive"
    dry_run: bool = False  # log the decisions, publish nothing
    log_every_s: float = 5.0  # a line of decisions, rate and latency this often


def run_drive_node(
    policy_spec: PolicySpec, config: DriveNodeConfig, driver: dict, weights: str | None = None,
    device: str = "cpu",
) -> tuple[int, str]:
    """Drive until shutdown; returns the exit status (0, or 1 when the watchdog failed or the master went
    away) and the last statistics line. `driver`: DriverConfig's fields other than the rate (the policy's
    own unless `driver['decision_hz']` is given)."""
    rospy = import_rospy()
    require_master()
    import rosgraph
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import CompressedImage, Image

    hz = driver.pop("decision_hz", None)
    policy, rate, frame_size = robot_policy(policy_spec, weights=weights, device=device, hz=hz)
    core = RobotDriver(policy, DriverConfig(decision_hz=rate, **driver), frame_size)
    compressed = config.image_topic.rstrip("/").endswith("/compressed")
    master = urlparse(rosgraph.get_master_uri())

    rospy.init_node(config.node_name)
    pub = None if config.dry_run else rospy.Publisher(config.cmd_topic, Twist, queue_size=1, tcp_nodelay=True)
    lock = threading.Lock()  # the loops and the shutdown hook publish one at a time
    done = threading.Event()
    status = [0]
    dropped: list[str] = []  # why the last frame was dropped, set by the camera's thread

    def publish(command: Command) -> None:
        msg = Twist()
        msg.linear.x, msg.angular.z = command.twist.linear_x, command.twist.angular_z
        if pub is not None:
            pub.publish(msg)
        if command.stamp is not None:  # each decision: at info level in a dry run, where it is all there is
            log = rospy.loginfo if pub is None else rospy.logdebug
            log("decision %.3f rad/s on the frame of %.3f s", command.twist.angular_z, command.stamp)
        else:
            rospy.loginfo("%s: zero twist%s", command.reason, " (dry run)" if pub is None else "")

    def fatal(why: str) -> None:
        """A zero twist, the reason logged, the node ended with an error (for a supervisor to restart it)."""
        with lock:
            try:
                if pub is not None:
                    pub.publish(Twist())
            finally:
                rospy.logfatal("%s: zero twist, the node exits with an error", why)
                status[0] = 1
                done.set()
        rospy.signal_shutdown(why)  # runs the shutdown hook, which takes the lock, in this thread

    def on_image(msg) -> None:
        stamp = msg.header.stamp.to_sec()
        frame = (Frame(stamp, bytes(msg.data)) if compressed
                 else Frame(stamp, bytes(msg.data), msg.encoding, msg.height, msg.width, msg.step))
        why = core.on_frame(frame, rospy.get_time())
        if why is not None:
            dropped[:] = [why]

    clock = {"ros": None, "wall": None}

    def watch_once() -> None:
        now, wall = rospy.get_time(), time.monotonic()
        last, last_wall = clock["ros"], clock["wall"]
        clock["ros"], clock["wall"] = now, wall
        jumps = core.stats.clock_jumps
        with lock:
            command = core.watch(now)  # the core tells a jump back (it drops the old clock's frames)
            if command is not None:
                publish(command)
        if core.stats.clock_jumps > jumps:
            rospy.logwarn("the clock jumped back from %.3f to %.3f s: everything stamped before is dropped",
                          last, now)
        elif last is not None and now - last > wall - last_wall + FORWARD_JUMP_S:
            rospy.logwarn("the clock jumped forward from %.3f to %.3f s", last, now)

    said: dict[str, float] = {}

    def say_at_most_once_a_second(key: str, message: str) -> None:
        """rospy's own throttles read the ROS clock, and stay silent after it runs back."""
        wall = time.monotonic()
        if wall - said.get(key, -math.inf) >= 1.0:
            said[key] = wall
            rospy.logerr(message)

    def decide_once() -> None:
        command = core.decide(rospy.get_time())
        if command is None:
            return
        if command.stamp is None:
            say_at_most_once_a_second("policy", f"the policy failed ({core.failure}): zero twist")
        with lock:
            if core.commit(command, rospy.get_time()):
                publish(command)

    misses, marks = [0], {"master": 0.0, "stats": time.monotonic(), "drops": 0.0}
    counted = [0]

    def monitor_once() -> None:
        wall = time.monotonic()
        if wall - marks["master"] >= MASTER_CHECK_S:
            marks["master"] = wall
            misses[0] = 0 if _answers(master.hostname or "localhost", master.port or 11311) else misses[0] + 1
            if misses[0] >= MASTER_MISSES:
                fatal(f"the ROS master at {master.geturl()} is gone")
                return
        stats = core.stats
        total = stats.bad + stats.stale + stats.future
        if total > counted[0] and wall - marks["drops"] >= DROPS_EVERY_S:
            rospy.logwarn("%d frames dropped (%d bad, %d stale, %d from another clock in all); the last: %s",
                          total - counted[0], stats.bad, stats.stale, stats.future, "".join(dropped))
            counted[0], marks["drops"] = total, wall
        if wall - marks["stats"] >= config.log_every_s:
            marks["stats"] = wall
            rospy.loginfo(stats.line())

    def watchdog_failed(err: BaseException) -> None:
        fatal(f"the watchdog failed ({type(err).__name__}: {err}); {traceback.format_exc(limit=-3)}")

    def failed(loop: str) -> Callable[[BaseException], None]:
        def log(err: BaseException) -> None:
            say_at_most_once_a_second(loop, f"the {loop} loop failed ({type(err).__name__}: {err}) and goes "
                                      f"on; the watchdog stops a robot whose decisions stall: "
                                      f"{traceback.format_exc(limit=-3)}")
        return log

    def on_shutdown() -> None:
        done.set()
        with lock:
            publish(core.stop())
            time.sleep(0.2)  # the publisher's thread sends the zero twist before rospy closes it
        rospy.loginfo("stopped: %s", core.stats.line())

    rospy.on_shutdown(on_shutdown)
    rospy.Subscriber(config.image_topic, CompressedImage if compressed else Image, on_image,
                     queue_size=1, buff_size=BUFFER_BYTES, tcp_nodelay=True)
    period = 1.0 / core.config.check_hz
    loops = [
        threading.Thread(target=guarded_loop, args=(watch_once, period, done, watchdog_failed, True),
                         name="watchdog", daemon=True),
        threading.Thread(target=guarded_loop, args=(decide_once, period, done, failed("decision"), False),
                         name="decisions", daemon=True),
        threading.Thread(target=guarded_loop, args=(monitor_once, 0.1, done, failed("monitor"), False),
                         name="monitor", daemon=True),
    ]
    for loop in loops:
        loop.start()
    rospy.loginfo(
        "%s: %s decisions at %.2f Hz on %s (%s), commands on %s%s", config.node_name, policy.name, rate,
        config.image_topic, "CompressedImage" if compressed else "Image", config.cmd_topic,
        " (dry run: not published)" if config.dry_run else "",
    )
    rospy.spin()
    done.set()
    for loop in loops:
        loop.join(timeout=1.0)
    return status[0], core.stats.line()


def guarded_loop(
    body: Callable[[], None], period_s: float, done: threading.Event,
    on_error: Callable[[BaseException], None], fatal: bool,
) -> None:
    """`body()` every `period_s` wall seconds until `done` is set. An exception goes to `on_error`, and
    the loop goes on, unless `fatal`: then it ends after `on_error`."""
    next_at = time.monotonic()
    while not done.is_set():
        try:
            body()
        except Exception as err:
            on_error(err)
            if fatal:
                return
        next_at = max(next_at + period_s, time.monotonic())
        done.wait(next_at - time.monotonic())


def _answers(host: str, port: int) -> bool:
    """Whether something accepts a TCP connection at host:port within a second."""
    try:
        with socket.create_connection((host, port), timeout=1.0):
            return True
    except OSError:
        return False
