"""What a robot's node does with each camera frame: decode it, decide, command. Free of ROS, so it is
tested here (rclpy cannot be installed from PyPI); `examples/turtlebot3_ros2.py` is the thin node
around it."""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from PIL import Image, UnidentifiedImageError

from depthq.control.policy import Policy
from depthq.errors import DataError

LINEAR_SPEED = 0.5  # m/s, the paper's constant forward speed


@dataclass(frozen=True)
class Twist:
    """A `geometry_msgs/Twist` in the two fields a TurtleBot3 uses: m/s forward, rad/s yaw (+left)."""

    linear_x: float
    angular_z: float


def decode_frame(data: bytes) -> np.ndarray:
    """A `sensor_msgs/CompressedImage` payload (JPEG or PNG) → uint8 RGB (H, W, 3)."""
    try:
        with Image.open(io.BytesIO(data)) as image:
            return np.array(image.convert("RGB"), dtype=np.uint8)  # a writable copy, as torch wants
    except (UnidentifiedImageError, OSError) as err:
        raise DataError(f"camera frame: not a JPEG or PNG image ({len(data)} bytes: {err})") from err


def twist_for_frame(policy: Policy, frame: np.ndarray) -> Twist:
    """One decision per frame: drive forward at LINEAR_SPEED, steer as the policy says."""
    return Twist(LINEAR_SPEED, float(policy.act({"image": frame})))
