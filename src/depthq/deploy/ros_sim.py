"""`depthq ros sim`: the simulated TurtleBot3 in its canyon as a ROS 1 robot (`depthq.deploy.canyon_robot`).

Publishes, stamped with the simulated time:

    /camera/image_raw/compressed  sensor_msgs/CompressedImage  JPEG frames at --camera-hz
    /scan                         sensor_msgs/LaserScan        the LDS-01's 360 beams, 1° apart from ahead
                                                               counter-clockwise, 5 Hz
    /odom                         nav_msgs/Odometry            pose and velocity, 30 Hz
    /clock                        rosgraph_msgs/Clock          the simulated time, 200 Hz
    /collision                    std_msgs/String              "bump" or "contact", the run's end (latched)

and moves the robot by the last `geometry_msgs/Twist` on /cmd_vel. It sets the master's
`/use_sim_time`, as Gazebo's launch files do: nodes started after it run on the simulated clock.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from depthq.deploy.canyon_robot import LDS01_HZ, CanyonRobot, RobotSimConfig
from depthq.deploy.robot import Twist
from depthq.deploy.ros1 import import_rospy, require_master
from depthq.sim.env import COLLISIONS


def run_sim_node(config: RobotSimConfig, speed: float = 1.0, wait_s: float = 60.0) -> dict[str, Any]:
    """One run at `speed` × real time; `wait_s` wall seconds for a first moving command, else the run
    ends as "no_command". Returns the summary (`CanyonRobot.summary`). SIGINT ends it as "interrupted"."""
    rospy = import_rospy()
    require_master()
    from geometry_msgs.msg import Twist as TwistMsg
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CompressedImage, LaserScan
    from std_msgs.msg import String

    robot = CanyonRobot(config)
    lidar = robot.world.config.lidar
    rospy.init_node("depthq_sim", disable_signals=True)  # SIGINT: Python's KeyboardInterrupt, below
    rospy.set_param("/use_sim_time", True)
    camera = rospy.Publisher("/camera/image_raw/compressed", CompressedImage, queue_size=2)
    scans = rospy.Publisher("/scan", LaserScan, queue_size=2)
    odom = rospy.Publisher("/odom", Odometry, queue_size=5)
    clock = rospy.Publisher("/clock", Clock, queue_size=10)
    collision = rospy.Publisher("/collision", String, queue_size=1, latch=True)
    lock = threading.Lock()

    def on_cmd(msg) -> None:
        with lock:
            robot.receive(Twist(msg.linear.x, msg.angular.z))

    rospy.Subscriber("/cmd_vel", TwistMsg, on_cmd, queue_size=10, tcp_nodelay=True)
    rospy.loginfo("depthq_sim: %s ready, camera %.0f Hz; waiting for /cmd_vel", config.canyon,
                  config.camera_hz)

    wall0 = time.monotonic()
    reason = None
    try:
        while reason is None and not rospy.is_shutdown():
            with lock:
                tick = robot.tick()
                pose, command = robot.pose, robot.command
            stamp = rospy.Time.from_sec(tick.time)
            if tick.clock:
                clock.publish(Clock(clock=stamp))
            if tick.jpeg is not None:
                msg = CompressedImage(format="jpeg", data=tick.jpeg)
                msg.header.stamp, msg.header.frame_id = stamp, "camera_rgb_optical_frame"
                camera.publish(msg)
            if tick.scan is not None:
                scans.publish(_scan_msg(LaserScan, tick.scan, stamp, lidar))
            if tick.odom:
                odom.publish(_odom_msg(Odometry, pose, command, stamp))
            reason = tick.end_reason
            if reason is None and robot.start is None and time.monotonic() - wall0 > wait_s:
                reason = "no_command"
            ahead = wall0 + tick.time / speed - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)
    except KeyboardInterrupt:
        reason = "interrupted"
    wall = time.monotonic() - wall0
    if reason in COLLISIONS:
        collision.publish(String(data=reason))
        time.sleep(0.2)  # the latched event reaches its subscribers before the node leaves
    summary = {**robot.summary(wall), "end_reason": reason}
    rospy.signal_shutdown(f"run ended: {reason}")
    robot.close()
    return summary


def _scan_msg(LaserScan, scan: np.ndarray, stamp, lidar) -> Any:
    msg = LaserScan()
    msg.header.stamp, msg.header.frame_id = stamp, "base_scan"
    msg.angle_min, msg.angle_increment = 0.0, float(np.deg2rad(1.0))
    msg.angle_max = float(np.deg2rad(len(scan) - 1))
    msg.scan_time = 1.0 / LDS01_HZ
    msg.time_increment = msg.scan_time / len(scan)
    msg.range_min, msg.range_max = lidar.range_min, lidar.range_max
    msg.ranges = scan.astype(float).tolist()
    return msg


def _odom_msg(Odometry, pose: np.ndarray, command: Twist, stamp) -> Any:
    msg = Odometry()
    msg.header.stamp, msg.header.frame_id, msg.child_frame_id = stamp, "odom", "base_footprint"
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(pose[0]), float(pose[1])
    msg.pose.pose.orientation.z = float(np.sin(pose[2] / 2))
    msg.pose.pose.orientation.w = float(np.cos(pose[2] / 2))
    msg.twist.twist.linear.x, msg.twist.twist.angular.z = command.linear_x, command.angular_z
    return msg
