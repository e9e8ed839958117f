"""Simulation: canyon geometry, the MuJoCo world, sensors and the Gymnasium env `depthq/Canyon-v0`."""

import gymnasium

import depthq  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)

ENV_ID = "depthq/Canyon-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="depthq.sim.env:CanyonEnv")
