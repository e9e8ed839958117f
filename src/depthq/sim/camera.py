"""Offscreen camera rendering that outlives the model.

`mujoco.Renderer` binds one MjModel for its lifetime and creating one costs ≈ 50 ms (GL context,
buffers). Every canyon is a freshly compiled model with the same assets, so this renderer keeps its
GL and MuJoCo rendering contexts and takes the model at each `render` call.
"""

from __future__ import annotations

import mujoco
import numpy as np
from mujoco import gl_context


class OffscreenCamera:
    """Render a named camera of any model built from the same MJCF assets, into a reused buffer."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, hidden_groups: tuple[int, ...] = (),
                 shown_groups: tuple[int, ...] = ()):
        self.width, self.height = width, height
        self._gl = gl_context.GLContext(width, height)
        self._gl.make_current()
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        self._scene = mujoco.MjvScene(model, maxgeom=2 * model.ngeom + 100)
        self._option = mujoco.MjvOption()
        for group in hidden_groups:
            self._option.geomgroup[group] = 0
        for group in shown_groups:  # MuJoCo shows groups 0–2 by default
            self._option.geomgroup[group] = 1
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._buffer = np.empty((height, width, 3), np.uint8)

    def render(self, model: mujoco.MjModel, data: mujoco.MjData, camera: str) -> np.ndarray:
        """uint8 (height, width, 3), top row first. The returned array is reused by the next call."""
        self._gl.make_current()
        self._camera.fixedcamid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        mujoco.mjv_updateScene(
            model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        mujoco.mjr_render(self._rect, self._scene, self._context)
        mujoco.mjr_readPixels(self._buffer, None, self._rect, self._context)
        return self._buffer[::-1]

    def upload(self, model: mujoco.MjModel, textures: list[int], meshes: list[int]) -> None:
        """Give the renderer `model`'s textures and meshes of these ids (changed after it was made)."""
        self._gl.make_current()
        for tex in textures:
            mujoco.mjr_uploadTexture(model, self._context, tex)
        for mesh in meshes:
            mujoco.mjr_uploadMesh(model, self._context, mesh)

    def close(self) -> None:
        if self._gl is not None:
            self._context.free()
            self._gl.free()
            self._gl = None
