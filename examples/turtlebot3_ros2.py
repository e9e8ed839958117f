"""A TurtleBot3 driven by an exported depthq policy: compressed camera frames in, cmd_vel out.

    pip install "depthq[deploy]"            # on the robot; rclpy comes with ROS 2
    depthq export runs/dqn --out policy/    # on the training machine (--frame-size HxW: your camera)
    python examples/turtlebot3_ros2.py policy/dqn.onnx

The logic is `depthq.deploy.robot` (tested in depthq's suite); this file only wires it to ROS 2.
"""

import sys

import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node
from sensor_msgs.msg import CompressedImage

from depthq.deploy.robot import decode_frame, twist_for_frame
from depthq.policies.onnx import OnnxPolicy


class DepthqDriver(Node):
    def __init__(self, onnx_path: str) -> None:
        super().__init__("depthq_driver")
        self.policy = OnnxPolicy(onnx_path)
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 1)
        self.create_subscription(CompressedImage, "/camera/image_raw/compressed", self.on_frame, 1)

    def on_frame(self, msg: CompressedImage) -> None:
        decision = twist_for_frame(self.policy, decode_frame(bytes(msg.data)))
        twist = Twist()
        twist.linear.x, twist.angular.z = decision.linear_x, decision.angular_z
        self.cmd.publish(twist)

    def stop(self) -> None:
        self.cmd.publish(Twist())  # all zeros: stand still


def main() -> None:
    rclpy.init()
    node = DepthqDriver(sys.argv[1])
    try:
        rclpy.spin(node)
    finally:
        node.stop()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
