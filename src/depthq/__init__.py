"""depthq: learn monocular collision avoidance from future depth (Depth-Q-Net) or collisions (Coll-Q-Net)."""

import os

# Offscreen rendering must be chosen before mujoco is imported anywhere.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"

# `import depthq` registers depthq/Canyon-v0 (as ale_py does for ALE/…), so that
# gymnasium.make("depthq/Canyon-v0") works after it and gymnasium.make("depthq:depthq/Canyon-v0")
# without it. Registering stores a name only: mujoco is imported when the env is made.
from depthq.sim import ENV_ID

__all__ = ["ENV_ID", "__version__"]
