"""`depthq ros drive`: a ROS 1 node around `depthq.deploy.robot.RobotDriver`, camera in, /cmd_vel out.

The camera topic's type follows image_transport's naming: a topic ending in `/compressed` carries
`sensor_msgs/CompressedImage` (JPEG or PNG), any other `sensor_msgs/Image` (rgb8, bgr8, mono8). The
subscription keeps one message (queue 1, a receive buffer larger than a frame, so that rospy never
delivers an old one); a timer at `check_hz` asks the core what to publish. On shutdown (SIGINT,
`rosnode kill`, the master gone) the node publishes a zero twist before it leaves.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from depthq.deploy.robot import Command, DriverConfig, Frame, RobotDriver, robot_policy
from depthq.deploy.ros1 import import_rospy, require_master

BUFFER_BYTES = 1 << 24  # rospy's receive buffer: larger than any frame, or it delivers stale ones
CLOCKS_APART_S = 10.0  # a frame this far from the node's clock: not a late frame but another clock


@dataclass(frozen=True)
class DriveNodeConfig:
    """The node's topics and logging; `driver` how it decides (`DriverConfig`)."""

    image_topic: str = "/camera/image_raw/compressed"
    cmd_topic: str = "/cmd_vel"
    node_name: str = "depthq_drive"
    dry_run: bool = False  # log the decisions, publish nothing
    log_every_s: float = 5.0  # a line of decisions, rate and latency this often


def run_drive_node(
    policy_spec: str, config: DriveNodeConfig, driver: dict, weights: str | None = None, device: str = "cpu"
) -> str:
    """Drive until shutdown; returns the last statistics line. `driver`: DriverConfig's fields other
    than the rate (the policy's own unless `driver['decision_hz']` is given)."""
    rospy = import_rospy()
    require_master()
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import CompressedImage, Image

    hz = driver.pop("decision_hz", None)
    policy, rate, frame_size = robot_policy(policy_spec, weights=weights, device=device, hz=hz)
    core = RobotDriver(policy, DriverConfig(decision_hz=rate, **driver), frame_size)
    compressed = config.image_topic.rstrip("/").endswith("/compressed")

    rospy.init_node(config.node_name)
    pub = None if config.dry_run else rospy.Publisher(config.cmd_topic, Twist, queue_size=1, tcp_nodelay=True)
    lock = threading.Lock()  # timer threads and the shutdown hook publish one at a time

    def publish(command: Command) -> None:
        msg = Twist()
        msg.linear.x, msg.angular.z = command.twist.linear_x, command.twist.angular_z
        if pub is not None:
            pub.publish(msg)
        now = rospy.get_time()
        core.published(command, now)
        if command.stamp is not None:  # each decision: at info level in a dry run, where it is all there is
            log = rospy.loginfo if pub is None else rospy.logdebug
            log("decision %.3f rad/s on the frame of %.3f s, %.0f ms old", command.twist.angular_z,
                command.stamp, 1e3 * (now - command.stamp))
        else:
            rospy.loginfo("%s: zero twist%s", command.reason, " (dry run)" if pub is None else "")

    def on_image(msg) -> None:
        stamp = msg.header.stamp.to_sec()
        frame = (Frame(stamp, bytes(msg.data)) if compressed
                 else Frame(stamp, bytes(msg.data), msg.encoding, msg.height, msg.width, msg.step))
        now = rospy.get_time()
        core.on_frame(frame, now)
        if abs(now - stamp) > CLOCKS_APART_S:
            rospy.logwarn_throttle(
                5.0, f"frames are stamped {now - stamp:.0f} s away from this node's clock, all stale: the "
                "camera's and this node's clocks differ (under depthq ros sim, start this node after the "
                "sim is ready, or `rosparam set /use_sim_time true` before either)")

    def on_tick(_event) -> None:
        with lock:
            if rospy.is_shutdown():
                return
            command = core.tick(rospy.get_time())
            if command is not None:
                publish(command)

    def on_shutdown() -> None:
        with lock:
            publish(core.stop())
            time.sleep(0.2)  # the publisher's thread sends the zero twist before rospy closes it
        rospy.loginfo("stopped: %s", core.stats.line())

    rospy.on_shutdown(on_shutdown)
    rospy.Subscriber(config.image_topic, CompressedImage if compressed else Image, on_image,
                     queue_size=1, buff_size=BUFFER_BYTES, tcp_nodelay=True)
    rospy.Timer(rospy.Duration(1.0 / core.config.check_hz), on_tick)
    rospy.Timer(rospy.Duration(config.log_every_s), lambda _e: rospy.loginfo(core.stats.line()))
    rospy.loginfo(
        "%s: %s decisions at %.2f Hz on %s (%s), commands on %s%s", config.node_name, policy.name, rate,
        config.image_topic, "CompressedImage" if compressed else "Image", config.cmd_topic,
        " (dry run: not published)" if config.dry_run else "",
    )
    rospy.spin()
    return core.stats.line()
