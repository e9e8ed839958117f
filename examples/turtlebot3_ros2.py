"""A TurtleBot3 driven by a depthq policy on ROS 2: camera frames in, cmd_vel out. UNTESTED: rclpy
installs from neither PyPI nor Debian 12, so no test here has ever run this file.

    pip install "depthq[deploy]"            # on the robot; rclpy comes with ROS 2
    depthq export runs/dqn --out policy/    # on the training machine (--frame-size HxW: your camera)
    python examples/turtlebot3_ros2.py policy/dqn.onnx [/camera/image_raw/compressed]

All the logic is `depthq.deploy.robot.RobotDriver`, the core that `depthq ros drive` (ROS 1, tested
through a real master in depthq's suite) runs too: decisions at the policy's trained rate on the newest
frame, a zero twist when frames stop for 0.5 s and on shutdown, any frame size and encoding. This
file only wires it to rclpy (docs/robot.md#ros2).
"""

import sys

import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, Image

from depthq.deploy.robot import DriverConfig, Frame, RobotDriver, robot_policy


class DepthqDriver(Node):
    def __init__(self, policy_spec: str, topic: str) -> None:
        super().__init__("depthq_drive")
        policy, rate, frame_size = robot_policy(policy_spec)
        self.core = RobotDriver(policy, DriverConfig(decision_hz=rate), frame_size)
        self.compressed = topic.rstrip("/").endswith("/compressed")
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 1)
        qos = qos_profile_sensor_data  # best effort, depth 1: the newest frame only
        self.create_subscription(CompressedImage if self.compressed else Image, topic, self.on_frame, qos)
        self.create_timer(1.0 / self.core.config.check_hz, self.on_tick)

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def on_frame(self, msg) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        frame = (Frame(stamp, bytes(msg.data)) if self.compressed
                 else Frame(stamp, bytes(msg.data), msg.encoding, msg.height, msg.width, msg.step))
        self.core.on_frame(frame, self.now())

    def publish(self, command) -> None:
        twist = Twist()
        twist.linear.x, twist.angular.z = command.twist.linear_x, command.twist.angular_z
        self.cmd.publish(twist)

    def on_tick(self) -> None:
        command = self.core.tick(self.now())
        if command is not None:
            self.publish(command)


def main() -> None:
    rclpy.init()
    topic = sys.argv[2] if len(sys.argv) > 2 else "/camera/image_raw/compressed"
    node = DepthqDriver(f"onnx:{sys.argv[1]}" if sys.argv[1].endswith(".onnx") else sys.argv[1], topic)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.publish(node.core.stop())  # stand still
        node.get_logger().info(node.core.stats.line())
        rclpy.shutdown()


if __name__ == "__main__":
    main()
