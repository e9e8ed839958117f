"""ROS 1's Python client (rospy) for depthq's virtual environment, without letting the system's
packages shadow the environment's own.

Debian and Ubuntu install rospy and the message packages into the system Python's folder
(`/usr/lib/python3/dist-packages`), beside the system's own Pillow, numpy and others; ROS Noetic's
own packages live in `/opt/ros/noetic/lib/python3/dist-packages`. Put on `PYTHONPATH`, such a folder
comes before the environment's packages and shadows them (Debian 12's Pillow 9.4 before depthq's).
`import_rospy` appends the folders at the end of `sys.path` instead, as a `.pth` file in the
environment would (docs/robot.md#ros1-install): the environment's packages win, and what only the
system has (rospy, rospkg, the messages) is found there.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType

from depthq.errors import ConfigError

# What `depthq ros` needs, as Debian 12 and Ubuntu name the packages (ROS Noetic's: ros-noetic-ros-base).
DEBIAN_PACKAGES = (
    "ros-core python3-rospy python3-sensor-msgs python3-geometry-msgs python3-nav-msgs python3-std-msgs "
    "python3-rosgraph-msgs python3-rosbag python3-rosnode"
)
SYSTEM_FOLDERS = ("/opt/ros/noetic/lib/python3/dist-packages", "/usr/lib/python3/dist-packages")
MODULES = (
    "rospy", "sensor_msgs.msg", "geometry_msgs.msg", "nav_msgs.msg", "std_msgs.msg", "rosgraph_msgs.msg"
)
INSTALL = f"depthq ros needs ROS 1 (rospy and its messages): apt-get install {DEBIAN_PACKAGES}"


def import_rospy() -> ModuleType:
    """rospy, with the message modules `depthq ros` uses imported; the system's folders appended to
    `sys.path` if the environment has no rospy of its own. A ConfigError naming what to install if none."""
    missing = _import_all()
    if missing is not None:
        for folder in SYSTEM_FOLDERS:
            if Path(folder).is_dir() and folder not in sys.path:
                sys.path.append(folder)
        importlib.invalidate_caches()
        missing = _import_all()
    if missing is not None:
        raise ConfigError(f"{INSTALL} ({missing} is missing)")
    return importlib.import_module("rospy")


def require_master() -> None:
    """A ConfigError naming ROS_MASTER_URI when no master answers there (rospy would wait forever)."""
    import rosgraph

    if not rosgraph.is_master_online():
        raise ConfigError(f"no ROS master answers at {rosgraph.get_master_uri()}: start roscore, or set "
                          "ROS_MASTER_URI to the robot's master")


def _import_all() -> str | None:
    """None when every module imports, else the name of the first that does not."""
    for name in MODULES:
        try:
            importlib.import_module(name)
        except ImportError as err:
            return err.name or name
    return None
