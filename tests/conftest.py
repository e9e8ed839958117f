"""Shared fixtures. Rendering is real MuJoCo through EGL (software Mesa on CPU machines)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
