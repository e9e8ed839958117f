"""depthq: learn monocular collision avoidance from future depth (Depth-Q-Net) or collisions (Coll-Q-Net)."""

import os

# Offscreen rendering must be chosen before mujoco is imported anywhere.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"
