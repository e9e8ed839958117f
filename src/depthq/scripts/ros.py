"""ROS 1: drive a robot with a policy (`ros drive`), or be the simulated robot (`ros sim`)."""

from __future__ import annotations

import argparse
import json

from depthq.errors import ConfigError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    # Nothing here imports rospy or MuJoCo: `depthq ros --help` works on a machine without ROS.
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    drive = actions.add_parser("drive", help="a ROS 1 node: camera in, /cmd_vel out, at the policy's rate")
    drive.add_argument("--policy", required=True, help="a checkpoint folder or onnx:PATH (`depthq export`)")
    drive.add_argument("--image-topic", default="/camera/image_raw/compressed",
                       help="camera topic; a name ending in /compressed is sensor_msgs/CompressedImage "
                       "(JPEG, PNG), any other sensor_msgs/Image (rgb8, bgr8, mono8) [%(default)s]")
    drive.add_argument("--cmd-topic", default="/cmd_vel", help="where the twists go [%(default)s]")
    drive.add_argument("--hz", type=float, default=None,
                       help="decisions per second [the rate the policy was trained at: its checkpoint's or "
                       "its ONNX file's]")
    drive.add_argument("--watchdog", type=float, default=0.5,
                       help="seconds without a fresh frame that decodes after which the robot gets a zero "
                       "twist [%(default)s]")
    drive.add_argument("--max-age", type=float, default=0.5,
                       help="a frame stamped longer ago than this (s) is stale, one stamped further ahead of "
                       "this node's clock is from another clock: neither is decided on [%(default)s]")
    drive.add_argument("--max-pixels", type=int, default=None,
                       help="a frame of more pixels is dropped unread, as its decoding would hold up "
                       "decisions [4096 × 3072]")
    drive.add_argument("--weights", default=None, help="a checkpoint's weights: best, last, average, epoch:N")
    drive.add_argument("--device", default="cpu", help="torch device for a checkpoint [cpu]")
    drive.add_argument("--node-name", default="depthq_drive", help="the ROS node's name [%(default)s]")
    drive.add_argument("--dry-run", action="store_true", help="log the decisions, publish nothing")
    drive.add_argument("--log-every", type=float, default=5.0,
                       help="seconds between log lines of decisions, rate and latency [%(default)s]")

    sim = actions.add_parser("sim", help="the simulated TurtleBot3 in a canyon as a ROS 1 robot (camera, "
                             "/scan, /odom, /clock), moved by /cmd_vel")
    sim.add_argument("--canyon", default="hard/eval:0",
                     help="canyon id, e.g. hard/eval:3, val:1000 [%(default)s]")
    sim.add_argument("--camera-hz", type=float, default=30.0, help="camera frames per second [%(default)s]")
    sim.add_argument("--time-limit", type=float, default=None,
                     help="simulated seconds from the first moving command [the canyon family's "
                     "evaluation limit]")
    sim.add_argument("--speed", type=float, default=1.0,
                     help="simulated seconds per real second, ≥ 1 [%(default)s]")
    sim.add_argument("--wait", type=float, default=60.0,
                     help="real seconds to wait for a first moving command [%(default)s]")
    sim.add_argument("--camera-until", type=float, default=None,
                     help="simulated seconds of driving after which the camera stops, as a camera driver "
                     "that dies (a node's watchdog should stop the robot) [never]")
    sim.add_argument("--seed", type=int, default=0, help="seeds the sensors' noise [%(default)s]")
    sim.add_argument("--json", action="store_true", help="print the summary as one JSON line")


def run(args: argparse.Namespace) -> int:
    if args.action == "drive":
        return _drive(args)
    return _sim(args)


def _drive(args: argparse.Namespace) -> int:
    from depthq.deploy.robot import DriverConfig
    from depthq.deploy.ros1 import import_rospy
    from depthq.deploy.ros_drive import DriveNodeConfig, run_drive_node
    from depthq.policies.spec import PolicySpec

    driver = {"watchdog_s": args.watchdog, "max_age_s": args.max_age}
    if args.max_pixels is not None:
        driver["max_pixels"] = args.max_pixels
    DriverConfig(decision_hz=args.hz or 1.0, **driver)  # the flags checked before anything loads
    if args.hz is not None:
        driver["decision_hz"] = args.hz
    import_rospy()  # no ROS: the one line naming what to install, before the policy loads
    if not args.log_every > 0:
        raise ConfigError(f"--log-every must be > 0 s, got {args.log_every}")
    config = DriveNodeConfig(args.image_topic, args.cmd_topic, args.node_name, args.dry_run, args.log_every)
    spec = PolicySpec.parse(args.policy)
    status, line = run_drive_node(spec, config, driver, weights=args.weights, device=args.device)
    print(line)
    return status


def _sim(args: argparse.Namespace) -> int:
    from depthq.deploy.ros1 import import_rospy

    if not args.speed >= 1:
        raise ConfigError(f"--speed must be ≥ 1 (real time or faster), got {args.speed}")
    if not args.wait > 0:
        raise ConfigError(f"--wait must be > 0 s, got {args.wait}")
    from depthq.deploy.canyon_robot import RobotSimConfig  # MuJoCo: when this verb runs

    config = RobotSimConfig(canyon=args.canyon, camera_hz=args.camera_hz, time_limit_s=args.time_limit,
                            seed=args.seed, camera_until_s=args.camera_until)
    import_rospy()  # no ROS: the one line naming what to install
    from depthq.deploy.ros_sim import run_sim_node

    s = run_sim_node(config, speed=args.speed, wait_s=args.wait)
    if args.json:
        print(json.dumps(s))
    else:
        print(
            f"{s['canyon']}: {s['distance']:.2f} m from the spawn in {s['time']:.1f} s, ended by "
            f"{s['end_reason']}; {s['commands']} commands at {s['command_hz']:.2f} Hz, {s['frames']} camera "
            f"frames at {s['camera_hz']:g} Hz, {s['real_time_factor']}× real time"
        )
    return 130 if s["end_reason"] == "interrupted" else 0
