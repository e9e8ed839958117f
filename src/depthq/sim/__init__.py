"""Simulation: canyon geometry, the MuJoCo world, sensors and the Gymnasium env `depthq/Canyon-v0`."""

import gymnasium

# No `import depthq` here: Python runs the package root (which sets MUJOCO_GL) before this.

ENV_ID = "depthq/Canyon-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="depthq.sim.env:CanyonEnv")
